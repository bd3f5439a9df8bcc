"""Closed-loop-only paths of the fitters: what a recording made only while the robot runs
its task can say that the fitters' general paths cannot (the latency's sensor set)."""
from __future__ import annotations

import numpy as np

from . import effects as fx


def latency_set(target, sensors: tuple, delay: int, kinds, families) -> tuple:
    """(sensors, delay) of a closed-loop latency refined one sensor at a time: each sensor
    is added to or dropped from the set where that lowers the objective on ``families``,
    then the delay chosen again.  Which sensors' turn responses lag is a poor guide when
    a turn error moves them too, and a latency on the wrong sensors distorts the noise
    statistics a sensor effect beside it is judged on."""
    def cost(s, d):
        return target.objective([fx.SensorLatency(s, d)], kinds, families) if s else np.inf
    best = cost(sensors, delay)
    for k in sorted(target.recordings[0].channels_used):
        trial = tuple(sorted(set(sensors) ^ {k}))
        value = cost(trial, delay)
        if value < best:
            sensors, best = trial, value
    delay = min((1, 2, 3), key=lambda d: best if d == delay else cost(sensors, d))
    return sensors, delay
