"""Hidden effects as small processes of their own, in shapes outside simple fitted families.

Every effect acts on one sample at a time, in the order the samples were taken
(``t`` counts samples over the whole recording), so the same code serves a
stationary recording and a closed loop in which the controller reacts to what
the effect did.  Readings follow the Khepera convention: 0 brightest, 525
darkest.  ``sensors`` is where the effect lives (the answer the diagnosis
should name); an actuator effect lives on no sensor.
"""
from __future__ import annotations

import math

import numpy as np

DARK = 525.0
SENSORS = 8


class Effect:
    """One hidden effect: a vocabulary name, a shape, where it lives and its settings."""

    name = 'none'
    delay = 0             # samples the readings arrive late (sensor_latency)

    def __init__(self, shape: str, sensors, **params):
        self.shape = shape
        self.sensors = sorted(int(s) for s in sensors)
        self.params = params

    def prepare(self, samples: int, clean: np.ndarray | None, rng) -> None:
        """Draw anything that depends on the length (and, offline, the clean readings)."""

    def sense(self, t: int, row: np.ndarray, rng) -> np.ndarray:
        return row

    def actuate(self, power: int, rng) -> int:
        return power

    def describe(self) -> dict:
        return {'name': self.name, 'shape': self.shape, 'sensors': self.sensors,
                'params': {k: _plain(v) for k, v in self.params.items()}}


def _plain(v):
    if isinstance(v, (list, tuple, np.ndarray)):
        return [_plain(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    return v


# -- spread laws --------------------------------------------------------------------------

def spread_law(law: str, p: dict, level: np.ndarray) -> np.ndarray:
    """Extra standard deviation (reading units) at ``level``; brightness b = 1 - level/525."""
    b = np.clip(1.0 - level / DARK, 0.0, 1.0)
    d = 1.0 - b
    if law == 'bright_power':          # grows with brightness, any power
        return p['a'] * b ** p['power']
    if law == 'dark_power':            # grows with darkness
        return p['a'] * d ** p['power']
    if law == 'affine':                # a constant part plus a part growing with brightness
        return p['c'] + p['a'] * b
    if law == 'log':                   # saturating growth with brightness
        return p['a'] * np.log1p(p['k'] * b) / math.log1p(p['k'])
    if law == 'piecewise':             # a step: noisy only above a brightness threshold
        return np.where(b > p['knee'], p['a'], p['a'] * p['low'])
    raise ValueError(f'unknown spread law {law!r}')


class Spread(Effect):
    """Zero-mean noise whose spread follows a law of the level, per sensor or shared."""

    name = 'intensity_dependent_noise'

    def sense(self, t, row, rng):
        sd = spread_law(self.shape, self.params, row[self.sensors])
        sd = sd * np.asarray(self.params['scale'])
        if self.params['tails'] == 'laplace':
            extra = rng.laplace(0.0, sd / math.sqrt(2.0))
        else:
            extra = rng.normal(0.0, sd)
        row = row.copy()
        row[self.sensors] += extra
        return row


# -- shared fast noise --------------------------------------------------------------------

class Groups(Effect):
    """Fast noise shared within groups of any sensors (each group its own source)."""

    name = 'correlated_noise'

    def sense(self, t, row, rng):
        row = row.copy()
        for group, sd, weights in zip(self.params['groups'], self.params['sd'],
                                      self.params['weights']):
            row[group] += rng.normal(0.0, sd) * np.asarray(weights)
        return row


# -- slow change --------------------------------------------------------------------------

class Drift(Effect):
    """Slow change: random walk, sinusoid, steps or a ramp; one for all or one per sensor."""

    name = 'temporal_drift'

    def prepare(self, samples, clean, rng):
        k = 1 if self.params['shared'] else len(self.sensors)
        amp = self.params['amplitude']
        t = np.arange(samples)[:, None]
        if self.shape == 'random_walk':
            walk = np.cumsum(rng.normal(0.0, 1.0, (samples, k)), axis=0)
            walk -= walk.mean(axis=0)
            path = amp * walk / max(np.abs(walk).max(), 1e-9)
        elif self.shape == 'sinusoid':
            period = self.params['period_frac'] * samples
            phase = rng.uniform(0, 2 * math.pi, k)
            path = amp * np.sin(2 * math.pi * t / period + phase)
        elif self.shape == 'steps':
            jumps = np.zeros((samples, k))
            for j in range(k):
                at = rng.choice(np.arange(samples // 10, samples), self.params['jumps'],
                                replace=False)
                jumps[at, j] = rng.choice([-1.0, 1.0], at.size) * amp * rng.uniform(0.5, 1.0,
                                                                                    at.size)
            path = np.cumsum(jumps, axis=0)
        elif self.shape == 'ramp':
            sign = rng.choice([-1.0, 1.0], k)
            path = sign * amp * (t / max(samples - 1, 1) - 0.5) * 2
        else:
            raise ValueError(f'unknown drift shape {self.shape!r}')
        self.path = np.broadcast_to(path, (samples, len(self.sensors))).copy()

    def sense(self, t, row, rng):
        row = row.copy()
        row[self.sensors] += self.path[min(t, len(self.path) - 1)]
        return row


# -- limits -------------------------------------------------------------------------------

class Limit(Effect):
    """A floor at the brightest few percent, a ceiling, a coarse lattice, or dropouts."""

    name = 'saturation_quantization'

    def prepare(self, samples, clean, rng):
        q = self.params.get('percent')
        if self.shape == 'floor':
            source = clean[:, self.sensors] if clean is not None else None
            self.value = float(np.percentile(source, q)) if source is not None \
                else self.params['fallback']
        elif self.shape == 'ceiling':
            source = clean[:, self.sensors] if clean is not None else None
            self.value = float(np.percentile(source, 100 - q)) if source is not None \
                else self.params['fallback']
        self.params['value'] = getattr(self, 'value', None)

    def sense(self, t, row, rng):
        row = row.copy()
        s = self.sensors
        if self.shape == 'floor':
            row[s] = np.maximum(row[s], self.value)
        elif self.shape == 'ceiling':
            row[s] = np.minimum(row[s], self.value)
        elif self.shape == 'lattice':
            step = self.params['step']
            row[s] = np.round(row[s] / step) * step
        elif self.shape == 'dropout':
            hit = rng.random(len(s)) < self.params['rate']
            row[np.asarray(s)[hit]] = self.params['stuck_at']
        else:
            raise ValueError(f'unknown limit shape {self.shape!r}')
        return row


# -- calibration --------------------------------------------------------------------------

class GainOffset(Effect):
    """Per-sensor gain on the light's drop below ambient and an offset, on some sensors."""

    name = 'sensor_gain_offset'

    def sense(self, t, row, rng):
        row = row.copy()
        s = self.sensors
        gain = np.asarray(self.params['gain'])
        offset = np.asarray(self.params['offset'])
        row[s] = DARK - gain * (DARK - row[s]) + offset
        return row


# -- timing and actuation (closed loop only) ----------------------------------------------

class Latency(Effect):
    """The controller gets each reading ``delay`` samples late (handled by the runner)."""

    name = 'sensor_latency'

    def __init__(self, shape, sensors, **params):
        super().__init__(shape, sensors, **params)
        self.delay = int(params['steps'])


class TurnError(Effect):
    """The robot turns by a different power than commanded: a scale, a slip, or both."""

    name = 'actuator_turn_error'

    def actuate(self, power, rng):
        executed = power * self.params['scale'] + rng.normal(0.0, self.params['slip'])
        low = math.floor(executed)
        executed = low + (rng.random() < executed - low)   # unbiased rounding
        return int(max(executed, 0))


KINDS = {cls.name: cls for cls in (Spread, Groups, Drift, Limit, GainOffset, Latency,
                                   TurnError)}
CLOSED_LOOP_ONLY = ('sensor_latency', 'actuator_turn_error')
