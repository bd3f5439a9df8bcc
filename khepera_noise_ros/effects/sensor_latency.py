"""``sensor_latency``: readings arrive late by whole steps.

The fit: a step response that lags after a change of heading (stationary recordings),
else turn responses of the readings moved to a later step (closed loop), the sensors
and the delay chosen by the simulator among the located sets.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import Array, Candidate, Effect, Evidence, Stage, Step, columns, param, rows
from .fitting import CLOSED_LOOP, STATIONARY, Z_DETECT, by_sensor, names, present


@dataclass(frozen=True)
class SensorLatency(Effect, name='sensor_latency', stage=Stage.READING, free=1,
                    summary='readings arrive late, by whole steps'):
    """The ``sensors`` report the reading of ``steps`` samples ago (the first repeats)."""

    sensors: tuple[int, ...] = param((), 'sensors whose readings arrive late', 'sensors')
    steps: int = param(1, 'samples each reading arrives late', low=0, high=1000)

    def start(self, robots: int, channels: int, rng: np.random.Generator) -> Step:
        rows(self.sensors, channels)
        past: list[Array] = []

        def step(level: Array) -> Array:      # the whole-run path over the last samples
            past[:] = (past + [level.copy()])[-self.steps - 1:]
            out: Array = self.over_time(np.stack(past), rng)[-1]
            return out
        return step

    def over_time(self, level: Array, rng: np.random.Generator) -> Array:
        cols = columns(self.sensors, level.shape[1])
        out: Array = level.copy()
        # sample t reads sample max(t - steps, 0): slices, not a gather of every sample
        out[self.steps:, cols] = level[:max(level.shape[0] - self.steps, 0), cols]
        out[:self.steps, cols] = level[:1, cols]
        return out

    @classmethod
    def fit(cls, evidence: Evidence) -> Candidate:
        steps = evidence.rows('step_response')
        first = [r.key.sensors[0] for r in steps
                 if str(r.key.part).startswith('sample 0') and r.z > Z_DETECT]
        if first:
            sensors = tuple(sorted(first))
            cells = by_sensor(steps)     # the samples each sensor's response lags
            lag = [sum(float(np.clip(r.real, 0, 1)) for r in cells[s]) for s in set(sensors)]
            delay = max(1, int(round(np.median(lag))))
            timed = len({r.key.part for r in steps})     # samples the step response covers
            if delay >= timed:
                kinds = present(evidence, (STATIONARY,))
                delay = min(range(timed, timed + 4),
                            key=lambda d: evidence.objective([cls(sensors, d)], kinds))
            return Candidate(cls.name, cls(sensors, delay),
                             f'step response of {names(sensors)} lags {delay} sample(s)')
        turned = {r.key.sensors[0] for r in evidence.rows('sensor_turn_response')
                  if abs(r.z) > Z_DETECT}
        if not turned:
            return cls.nothing('readings follow heading changes at once')
        # sensors whose turn responses pass for simulated can lag too: their closed-loop
        # noise residuals then take the earlier heading's light; the simulator judges on
        # the statistics other than the noise ones (other sensor effects act there too)
        noisy = {r.key.sensors[0] for r in evidence.rows('loop_residual_spread') if r.z > Z_DETECT}
        options = {tuple(sorted(turned)), tuple(evidence.channels), tuple(sorted(turned | noisy))}
        delayed = evidence.delayed_sensors()
        if delayed:
            options.add(delayed)
        families = evidence.families() - evidence.families('closed_loop_noise')
        kinds = present(evidence, (CLOSED_LOOP,))
        sensors, delay = min(((o, d) for o in sorted(options) for d in (1, 2, 3)),
                             key=lambda o: evidence.objective([cls(*o)], kinds, families))
        return Candidate(cls.name, cls(sensors, delay),
                         f'turn responses of {names(sensors)} delayed {delay} step(s)')
