"""``sensor_response``: a sensor follows its light late and gradually.

A fractional delay, then a first-order lag with its own rate towards bright and towards
dark.  The fit: the step response after a change of heading (stationary
``step_response``, ``turn_step_response`` of rests after a turn) by least squares on its
analytic form.  A whole delay with rate 1 is ``sensor_latency``'s case, and so is a delay
seen only in the closed loop: there the turn responses alone confound a lag with the
turn made.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .base import (Array, Candidate, Effect, Evidence, Row, Stage, Step, columns, param, replaced,
                   rows)
from .fitting import Z_DETECT, names

DELAYS = np.round(np.arange(0.0, 3.0001, 0.05), 2)
RATES = np.round(np.arange(0.05, 1.0001, 0.05), 2)
WHOLE = 0.05          # a delay this near a whole step with rate 1 is sensor_latency's case


@dataclass(frozen=True)
class SensorResponse(Effect, name='sensor_response', stage=Stage.LIGHT, free=3,
                     summary='sensors follow their light late and gradually (delay and lag)'):
    """Sensor s reads y[t] = y[t-1] + k (x[t - delay] - y[t-1]), k = ``rate_bright`` when
    the light brightens, ``rate_dark`` when it darkens, from a settled start."""

    sensors: tuple[int, ...] = param((), 'sensors that respond late or gradually', 'sensors')
    delay: float = param(0.0, 'delay, samples (fractions interpolate)', low=0.0, high=20.0)
    rate_bright: float = param(1.0, 'fraction of the way per sample towards bright',
                               above=0.0, high=1.0)
    rate_dark: float = param(1.0, 'fraction of the way per sample towards dark',
                             above=0.0, high=1.0)

    def start(self, robots: int, channels: int, rng: np.random.Generator) -> Step:
        located = rows(self.sensors, channels)
        n, f = int(math.floor(self.delay)), self.delay % 1
        past: list[Array] = []
        state: list[Array] = []

        def step(level: Array) -> Array:
            past[:] = (past + [level[located].copy()])[-n - 2:]
            a, b = past[max(0, len(past) - 1 - n)], past[max(0, len(past) - 2 - n)]
            x = (1 - f) * a + f * b
            if state:                               # else a settled start
                y = state[0]
                x = y + np.where(x < y, self.rate_bright, self.rate_dark) * (x - y)
            state[:] = [x]
            return replaced(level, located, x)
        return step

    def over_time(self, level: Array, rng: np.random.Generator) -> Array:
        cols = columns(self.sensors, level.shape[1])
        n, f = int(math.floor(self.delay)), self.delay % 1
        t = np.arange(level.shape[0])
        x = level[:, cols]
        x = (1 - f) * x[np.maximum(t - n, 0)] + f * x[np.maximum(t - n - 1, 0)]
        if self.rate_bright == 1.0 and self.rate_dark == 1.0:
            return replaced(level, cols, x)
        y = np.empty_like(x)
        y[0] = x[0]
        change = np.r_[0, np.flatnonzero((x[1:] != x[:-1]).reshape(len(x) - 1, -1)
                                         .any(axis=1)) + 1, len(x)]
        # within a stretch of one light the lag closes a fixed share per sample
        for t0, t1 in zip(np.maximum(change[:-1], 1), change[1:]):
            prev, target = y[t0 - 1], x[t0]
            k = np.where(target < prev, self.rate_bright, self.rate_dark)
            m = np.arange(1, t1 - t0 + 1).reshape((-1,) + (1,) * (x.ndim - 1))
            y[t0:t1] = target + (prev - target) * (1 - k) ** m
        return replaced(level, cols, y)

    @classmethod
    def fit(cls, evidence: Evidence) -> Candidate:
        steps = evidence.rows('step_response') + evidence.rows('turn_step_response')
        slow = sorted({r.key.sensors[0] for r in steps if r.z > Z_DETECT})
        if not slow:
            turned = any(abs(r.z) > Z_DETECT for r in evidence.rows('sensor_turn_response'))
            return cls.nothing('no step response slower than simulated (changes of heading, or '
                               'record --protocol turns)' + (
                                   '; the delay the closed loop shows is sensor_latency\'s'
                                   if turned else ''))
        delay, bright, dark = _analytic([r for r in steps if r.key.sensors[0] in slow])
        how = 'step responses' + (' after turns' if steps[-1].key.family.startswith(
            'turn') else ' after changes of heading')
        # sensors whose responses agree with the fit are taken to share it; those
        # nobody could time too, when every one that could be timed does
        timed = {r.key.sensors[0] for r in steps}
        slow = sorted(set(slow) | (timed - _faster(steps, delay, bright, dark)))
        if set(slow) >= timed:
            slow = sorted(set(slow) | set(evidence.channels))
        if min(bright, dark) >= 1.0 and delay >= 1 - WHOLE and abs(delay - round(delay)) <= WHOLE:
            return cls.nothing(f'{how}: a whole-step delay of {round(delay)} (sensor_latency\'s '
                               'case)')
        if delay == 0.0 and min(bright, dark) >= 1.0:
            return cls.nothing(f'{how}: no delay and no lag')
        effect = cls(tuple(slow), float(delay), float(bright), float(dark))
        return Candidate(cls.name, effect, f'{how} of {names(slow)}: delay {delay:g} samples, '
                         f'rate {bright:g} towards bright, {dark:g} towards dark')


def response(delay: float, rate: float, samples: int) -> Array:
    """Share of an old level left at samples 0.. after a step, the delay then the lag."""
    n, f = int(math.floor(delay)), delay - math.floor(delay)
    u = np.where(np.arange(samples) < n, 1.0, 0.0)
    if n < samples:
        u[n] = f
    out, r = np.empty(samples), 1.0
    for j in range(samples):
        r = (1 - rate) * r + rate * u[j]
        out[j] = r
    return out


def _analytic(steps: list[Row]) -> tuple[float, float, float]:
    """(delay, rate towards bright, towards dark) by weighted least squares of the real
    step responses (pooled rows count for both directions)."""
    def sample(r: Row) -> int:
        return int(str(r.key.part).split()[1])
    size = max(sample(r) for r in steps) + 1
    table = {(d, k): response(d, k, size) for d in DELAYS for k in RATES}
    sides = {side: [r for r in steps if side in str(r.key.part) or 'change' in str(r.key.part)]
             for side in ('bright', 'dark')}
    cells = {side: (np.array([sample(r) for r in mine]), np.array([r.real for r in mine]),
                    1.0 / np.maximum(np.array([r.se for r in mine]), 0.01) ** 2)
             for side, mine in sides.items() if mine}
    best = (math.inf, 0.0, 1.0, 1.0)
    for d in DELAYS:
        cost, rate = 0.0, {'bright': 1.0, 'dark': 1.0}
        for side, (j, real, w) in cells.items():
            errors = [float((w * (real - table[(d, k)][j]) ** 2).sum()) for k in RATES]
            i = int(np.argmin(errors))
            rate[side], cost = float(RATES[i]), cost + errors[i]
        if cost < best[0]:
            best = (cost, float(d), rate['bright'], rate['dark'])
    return best[1], best[2], best[3]


def _faster(steps: list[Row], delay: float, bright: float, dark: float) -> set[int]:
    """Sensors with a step response the fitted one does not explain (beyond ``Z_DETECT``)."""
    out = set()
    for r in steps:
        part = str(r.key.part)
        rate = dark if 'dark' in part else bright if 'bright' in part else (bright + dark) / 2
        model = response(delay, rate, int(part.split()[1]) + 1)[-1]
        if abs(r.real - model) > Z_DETECT * max(r.se, 0.01):
            out.add(r.key.sensors[0])
    return out
