"""Closed-loop-only paths of the fitters: what a recording made only while the robot runs
its task can say about a sensor's calibration.

With no stationary runs there are no levels by heading to fit a line to; each sensor
has one closed-loop mean level per condition (``closed_loop_level``).  A sensor whose
mean is off (chi-square over conditions, Holm) is given the offset that closes the gap,
and a gain about the dark anchor is tried in its place; the simulator picks.  One mean
cannot tell a gain from an offset where the sensor reads near one level; where it
reads at two conditions' levels the two are fitted as a line.
"""
from __future__ import annotations

import numpy as np
from scipy import stats as sps

from . import effects as fx
from .fitbase import Candidate, rows as _rows
from .where import ALPHA, holm

ANCHOR = 525.0


def gain_offset(target, c) -> Candidate | None:
    """A calibration from the closed-loop levels; None when there are none."""
    name = fx.SensorGainOffset.name
    level = _rows(c, 'closed_loop_level')
    if not level:
        return None
    sensors = sorted({k.sensors[0] for k, *_ in level})
    by = {s: [(r, m, z) for k, r, m, se, z in level if k.sensors[0] == s] for s in sensors}
    p = holm(np.array([sps.chi2.sf(sum(z * z for *_, z in by[s]), len(by[s]))
                       for s in sensors]))
    located = [s for s, ps in zip(sensors, p) if ps < ALPHA]
    if not located:
        return Candidate(name, None, 'no sensor\'s closed-loop level differs significantly')
    gains, offsets, scaled = [], [], []
    for s in located:
        real, sim = (np.array(v) for v in zip(*[(r, m) for r, m, _ in by[s]]))
        if real.size > 1 and np.ptp(sim) > 1:
            g, a = np.polyfit(sim, real, 1)
            gains.append(round(float(g), 4))
            offsets.append(round(float(a - ANCHOR * (1 - g)), 2))
        else:
            gains.append(1.0)
            offsets.append(round(float(np.mean(real - sim)), 2))
        # the same shift as a gain about the dark anchor (where the sensor is not dark)
        dark = ANCHOR - np.mean(sim)
        scaled.append(round(float(1 + np.mean(sim - real) / dark), 4) if dark > 5 else 1.0)
    effect = fx.SensorGainOffset(tuple(located), tuple(gains), tuple(offsets), ANCHOR)
    gain = fx.SensorGainOffset(tuple(located), tuple(scaled), (0.0,) * len(located), ANCHOR)
    if gain != effect and target.objective([gain]) < target.objective([effect]):
        effect = gain
    names = ', '.join(f's{s}' for s in located)
    return Candidate(name, effect, f'closed-loop levels of {names} off the light model')


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
