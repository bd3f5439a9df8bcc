"""Simulator-side models of the unmodelled effects, one per name of the effect vocabulary.

Each effect is a small physical process the simulator can add to the paper's
model.  Light-stage effects change the light level a sensor sees before the
model's noise is drawn (calibration, drift, flicker, shared group noise); the
reading stage acts on the noisy reading (latency, then the converter); the
turn stage changes a commanded rotation.  An effect's ``process(robots,
channels, rng)`` starts a fresh state for a batch of episodes.  Arrays are
(channels, robots), as in the core.

Effects are written to the simulator's ``effects`` parameter as a JSON list
(``dumps``/``loads``), so the fitted effect travels in the params YAML.
"""
from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..core.khepera import DARK

NAMES = ('correlated_noise', 'intensity_dependent_noise', 'sensor_gain_offset',
         'temporal_drift', 'actuator_turn_error', 'sensor_latency', 'saturation_quantization')
VOCABULARY = NAMES + ('none',)


def _rows(sensors, channels: int) -> list[int]:
    bad = [s for s in sensors if not 0 <= s < channels]
    if bad:
        raise ValueError(f'effect names sensors {bad}; the data has channels 0..{channels - 1}')
    return list(sensors)


class _OnSensors:
    """An effect located on a set of sensors."""

    @property
    def location(self) -> list:
        return list(self.sensors)


@dataclass(frozen=True)
class SensorGainOffset(_OnSensors):
    """Per-sensor calibration: reading = anchor - gain * (anchor - ideal) + offset."""

    name: ClassVar[str] = 'sensor_gain_offset'
    stage: ClassVar[str] = 'light'
    sensors: tuple = ()
    gains: tuple = ()
    offsets: tuple = ()
    anchor: float = DARK

    def process(self, robots: int, channels: int, rng):
        rows = _rows(self.sensors, channels)
        g = np.ones((channels, 1))
        o = np.zeros((channels, 1))
        g[rows, 0], o[rows, 0] = self.gains, self.offsets
        return lambda level: self.anchor - g * (self.anchor - level) + o

    def over_time(self, level: np.ndarray, rng) -> np.ndarray:
        return self.process(level.shape[2], level.shape[1], rng)(level)


@dataclass(frozen=True)
class TemporalDrift(_OnSensors):
    """Slow AR(1) wander of the sensors' gain: sd ``sd`` (a fraction), correlation time
    ``time_constant`` samples, one wander for all ``sensors`` if ``shared``."""

    name: ClassVar[str] = 'temporal_drift'
    stage: ClassVar[str] = 'light'
    sensors: tuple = ()
    sd: float = 0.01
    time_constant: float = 30.0
    shared: bool = True

    def process(self, robots: int, channels: int, rng):
        rows = _rows(self.sensors, channels)
        a = float(np.exp(-1.0 / self.time_constant))
        width = 1 if self.shared else len(rows)
        state = self.sd * rng.standard_normal((width, robots))

        def apply(level):
            nonlocal state
            out = level.copy()
            out[rows] *= 1.0 + state
            state = a * state + np.sqrt(1 - a * a) * self.sd * rng.standard_normal(state.shape)
            return out
        return apply

    def over_time(self, level: np.ndarray, rng) -> np.ndarray:
        """``process`` over (samples, channels, robots) at once: the AR(1) as a filter."""
        from scipy.signal import lfilter
        rows = _rows(self.sensors, level.shape[1])
        a = float(np.exp(-1.0 / self.time_constant))
        width = 1 if self.shared else len(rows)
        z = rng.standard_normal((level.shape[0], width, level.shape[2]))
        z[0] *= self.sd
        z[1:] *= np.sqrt(1 - a * a) * self.sd
        state = lfilter([1.0], [1.0, -a], z, axis=0)
        out = level.copy()
        cols = slice(None) if rows == list(range(level.shape[1])) else rows    # a view
        out[:, cols] *= 1.0 + state
        return out


@dataclass(frozen=True)
class IntensityDependentNoise(_OnSensors):
    """Noise whose sd follows a spread law of the level r (``gap.spreadlaw``):
    sd = constant + strength * u * (u / scale) ** exponent, u = r ('dark': larger the
    darker the reading, a room's flicker) or scale - r ('bright'); one draw for all
    ``sensors`` at once if ``shared`` (a flicker), else one per sensor."""

    name: ClassVar[str] = 'intensity_dependent_noise'
    stage: ClassVar[str] = 'light'
    sensors: tuple = ()
    strength: float = 0.03
    exponent: float = 1.0
    scale: float = DARK
    constant: float = 0.0
    direction: str = 'dark'
    shared: bool = True

    def amplitude(self, level: np.ndarray) -> np.ndarray:
        r = np.clip(level, 0.0, self.scale)
        u = r if self.direction == 'dark' else self.scale - r
        with np.errstate(divide='ignore', invalid='ignore'):
            law = np.where(u > 0, u * (u / self.scale) ** self.exponent, 0.0)
        return self.constant + self.strength * np.nan_to_num(law, posinf=0.0)

    def process(self, robots: int, channels: int, rng):
        rows = _rows(self.sensors, channels)

        def apply(level):
            out = level.copy()
            z = rng.standard_normal(robots if self.shared else (len(rows), robots))
            out[rows] += z * self.amplitude(level[rows])
            return out
        return apply

    def over_time(self, level: np.ndarray, rng) -> np.ndarray:
        rows = _rows(self.sensors, level.shape[1])
        out = level.copy()
        width = 1 if self.shared else len(rows)
        z = rng.standard_normal((level.shape[0], width, level.shape[2]))
        cols = slice(None) if rows == list(range(level.shape[1])) else rows    # a view
        out[:, cols] += z * _held(self.amplitude, level[:, cols])
        return out


def _held(f, x: np.ndarray) -> np.ndarray:
    """``f(x)`` of an elementwise ``f`` over (samples, ...) ``x``, computed only at the
    samples where ``x`` changes (a stationary light level holds for a whole run; the
    power law is the costly part of a replay): the same values."""
    if x.shape[0] < 2:
        return f(x)
    new = np.flatnonzero(np.r_[True, (x[1:] != x[:-1]).reshape(x.shape[0] - 1, -1).any(axis=1)])
    if new.size > x.shape[0] // 4:
        return f(x)
    return np.repeat(f(x[new]), np.diff(np.r_[new, x.shape[0]]), axis=0)


@dataclass(frozen=True)
class CorrelatedNoise:
    """Normal noise shared within each group, sd ``strength`` x the group's mean level
    (the paper's dependent noise) plus ``constant`` (readings, whatever the level)."""

    name: ClassVar[str] = 'correlated_noise'
    stage: ClassVar[str] = 'light'
    groups: tuple = ()
    strength: float = 0.01
    constant: float = 0.0

    def process(self, robots: int, channels: int, rng):
        groups = [_rows(g, channels) for g in self.groups]

        def apply(level):
            out = level.copy()
            z = rng.standard_normal((len(groups), robots))
            for g, members in enumerate(groups):
                out[members] += (self.strength * level[members].mean(axis=0)
                                 + self.constant) * z[g]
            return out
        return apply

    def over_time(self, level: np.ndarray, rng) -> np.ndarray:
        groups = [_rows(g, level.shape[1]) for g in self.groups]
        out = level.copy()
        z = rng.standard_normal((level.shape[0], len(groups), level.shape[2]))
        for g, members in enumerate(groups):
            sd = self.strength * level[:, members].mean(axis=1) + self.constant
            out[:, members] += (sd * z[:, g])[:, None]
        return out

    @property
    def location(self) -> list:
        return [list(g) for g in self.groups]

    @property
    def sensors(self) -> tuple:
        return tuple(sorted(s for g in self.groups for s in g))


@dataclass(frozen=True)
class SensorLatency(_OnSensors):
    """The ``sensors`` report the reading of ``steps`` samples ago (the first repeats)."""

    name: ClassVar[str] = 'sensor_latency'
    stage: ClassVar[str] = 'reading'
    sensors: tuple = ()
    steps: int = 1

    def process(self, robots: int, channels: int, rng):
        rows = _rows(self.sensors, channels)
        past: list = []

        def apply(level):
            past.append(level[rows].copy())
            out = level.copy()
            out[rows] = past[max(0, len(past) - 1 - self.steps)]
            del past[:-self.steps - 1]
            return out
        return apply

    def over_time(self, level: np.ndarray, rng) -> np.ndarray:
        rows = _rows(self.sensors, level.shape[1])
        out = level.copy()
        if self.steps <= 0:
            return out
        # sample t reads sample max(t - steps, 0): slices, not a gather of every sample
        cols = slice(None) if rows == list(range(level.shape[1])) else rows
        out[self.steps:, cols] = level[:max(level.shape[0] - self.steps, 0), cols]
        out[:self.steps, cols] = level[:1, cols]
        return out


@dataclass(frozen=True)
class SaturationQuantization(_OnSensors):
    """The converter: ``sensors`` rounded to the lattice origin + k * ``step``, then held in
    [low, high];
    with probability ``dropout`` a reading is lost and reads ``dropout_value`` instead
    (isolated readings stuck at zero or at a limit)."""

    name: ClassVar[str] = 'saturation_quantization'
    stage: ClassVar[str] = 'reading'
    sensors: tuple = ()
    low: float = 0.0
    high: float = DARK
    step: float = 1.0
    dropout: float = 0.0
    dropout_value: float = 0.0
    origin: float = 0.0           # the lattice is origin + k * step

    def _convert(self, x: np.ndarray, rng) -> np.ndarray:
        lattice = np.round((x - self.origin) / self.step) * self.step + self.origin
        out = np.clip(lattice, self.low, self.high)
        if self.dropout > 0:
            out = np.where(rng.random(out.shape) < self.dropout, self.dropout_value, out)
        return out

    def process(self, robots: int, channels: int, rng):
        rows = _rows(self.sensors, channels)

        def apply(level):
            out = level.copy()
            out[rows] = self._convert(level[rows], rng)
            return out
        return apply

    def over_time(self, level: np.ndarray, rng) -> np.ndarray:
        rows = _rows(self.sensors, level.shape[1])
        out = level.copy()
        out[:, rows] = self._convert(level[:, rows], rng)
        return out


@dataclass(frozen=True)
class ActuatorTurnError:
    """A commanded rotation of x degrees turns x * scale + slip * |x| * N(0, 1)
    + creep * N(0, 1) degrees: ``creep`` (degrees, default 0) is a slip of a fixed size,
    which turns the robot even at power 0.

    With ``knocks`` the task's heading knocks are scaled too: on a real robot (the
    hardware bridge) the knocks are turns made by the same wheels.
    """

    name: ClassVar[str] = 'actuator_turn_error'
    stage: ClassVar[str] = 'turn'
    scale: float = 1.0
    slip: float = 0.0
    knocks: bool = True
    creep: float = 0.0

    def process(self, robots: int, channels: int, rng):
        def turn(deg):
            out = deg * self.scale + self.slip * np.abs(deg) * rng.standard_normal(np.shape(deg))
            if self.creep:       # drawn only when set: older effects keep their streams
                out = out + self.creep * rng.standard_normal(np.shape(deg))
            return out
        return turn

    @property
    def location(self) -> list:
        return []

    @property
    def sensors(self) -> tuple:
        return ()


@dataclass(frozen=True)
class EmpiricalNoise(_OnSensors):
    """The remainder no named effect explains, as measured (not a vocabulary name).

    Fast part: per sensor an extra sd (readings) interpolated over ``levels`` from
    ``spread`` (one row of knots per sensor), mixed across the sensors by the lower
    triangular ``mixing`` (the fast part's correlation).  Slow part: an AR(1) of
    correlation time ``slow_time_constant`` samples moving each sensor's gain by
    ``slow_sd`` (fraction), mixed by ``slow_mixing``.
    """

    name: ClassVar[str] = 'empirical_noise'
    stage: ClassVar[str] = 'light'
    sensors: tuple = ()
    levels: tuple = (0.0, 525.0)
    spread: tuple = ()
    mixing: tuple = ()
    slow_sd: tuple = ()
    slow_time_constant: float = 30.0
    slow_mixing: tuple = ()

    def _arrays(self):
        n = len(self.sensors)
        spread = np.asarray(self.spread, float).reshape(n, len(self.levels))
        mix = np.asarray(self.mixing, float).reshape(n, n) if self.mixing else np.eye(n)
        slow = np.asarray(self.slow_sd, float) if self.slow_sd else np.zeros(n)
        smix = np.asarray(self.slow_mixing, float).reshape(n, n) if self.slow_mixing \
            else np.eye(n)
        return spread, mix, slow, smix

    def _fast(self, level_rows: np.ndarray, z: np.ndarray, spread, mix) -> np.ndarray:
        sd = np.stack([np.interp(level_rows[k], self.levels, spread[k])
                       for k in range(len(self.sensors))])
        return sd * np.einsum('ij,j...->i...', mix, z)

    def process(self, robots: int, channels: int, rng):
        rows = _rows(self.sensors, channels)
        spread, mix, slow, smix = self._arrays()
        a = float(np.exp(-1.0 / self.slow_time_constant))
        state = smix @ rng.standard_normal((len(rows), robots))

        def apply(level):
            nonlocal state
            out = level.copy()
            out[rows] = level[rows] * (1.0 + slow[:, None] * state) + self._fast(
                level[rows], rng.standard_normal((len(rows), robots)), spread, mix)
            state = a * state + np.sqrt(1 - a * a) * (smix @ rng.standard_normal(state.shape))
            return out
        return apply

    def over_time(self, level: np.ndarray, rng) -> np.ndarray:
        from scipy.signal import lfilter
        rows = _rows(self.sensors, level.shape[1])
        spread, mix, slow, smix = self._arrays()
        a = float(np.exp(-1.0 / self.slow_time_constant))
        t, n, r = level.shape[0], len(rows), level.shape[2]
        z = np.einsum('ij,tjr->tir', smix, rng.standard_normal((t, n, r)))
        z[1:] *= np.sqrt(1 - a * a)
        state = lfilter([1.0], [1.0, -a], z, axis=0)
        fast = self._fast(level[:, rows].transpose(1, 0, 2),
                          rng.standard_normal((n, t, r)), spread, mix).transpose(1, 0, 2)
        out = level.copy()
        out[:, rows] = level[:, rows] * (1.0 + slow[None, :, None] * state) + fast
        return out


TYPES = {cls.name: cls for cls in (CorrelatedNoise, IntensityDependentNoise, SensorGainOffset,
                                   TemporalDrift, ActuatorTurnError, SensorLatency,
                                   SaturationQuantization, EmpiricalNoise)}


def parameters(effect) -> dict:
    """The effect's fields as plain JSON values, without the location."""
    skip = {'sensors', 'groups'}
    return {f.name: _plain(getattr(effect, f.name)) for f in dataclasses.fields(effect)
            if f.name not in skip}


def to_dict(effect) -> dict:
    out = {'name': effect.name}
    out.update({f.name: _plain(getattr(effect, f.name)) for f in dataclasses.fields(effect)})
    return out


def from_dict(data: dict):
    """An effect from its dict form; a ValueError names what is wrong."""
    if not isinstance(data, dict) or data.get('name') not in TYPES:
        raise ValueError(f'an effect needs a name from {list(TYPES)}, got {data!r}')
    cls = TYPES[data['name']]
    allowed = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - allowed - {'name'})
    if unknown:
        raise ValueError(f'effect {data["name"]}: unknown field(s) {unknown}; allowed: '
                         f'{sorted(allowed)}')
    values = {k: _tuple(v) for k, v in data.items() if k != 'name'}
    effect = cls(**values)
    _check(effect)
    return effect


def _check(effect) -> None:
    location = getattr(effect, 'groups', None) or [getattr(effect, 'sensors', ())]
    for g in location:
        if any(not isinstance(s, int) or s < 0 for s in g):
            raise ValueError(f'effect {effect.name}: sensors must be indices >= 0, got {g!r}')
    numbers = [v for v in parameters(effect).values() if isinstance(v, (int, float))]
    if not all(np.isfinite(numbers)):
        raise ValueError(f'effect {effect.name}: parameters must be finite, '
                         f'got {parameters(effect)}')
    if effect.name == 'sensor_latency' and effect.steps < 0:
        raise ValueError(f'sensor_latency steps must be >= 0, got {effect.steps}')
    if effect.name == 'saturation_quantization' and (effect.step <= 0 or
                                                     effect.low >= effect.high or
                                                     not 0 <= effect.dropout < 1):
        raise ValueError(f'saturation_quantization needs step > 0, low < high and '
                         f'0 <= dropout < 1, got '
                         f'{parameters(effect)}')
    if effect.name == 'actuator_turn_error' and (effect.slip < 0 or effect.creep < 0):
        raise ValueError(f'actuator_turn_error needs slip >= 0 and creep >= 0, got '
                         f'{parameters(effect)}')
    if effect.name == 'empirical_noise':
        n = len(effect.sensors)
        if len(effect.levels) < 1 or len(effect.spread) != n * len(effect.levels) or \
                len(effect.mixing) not in (0, n * n) or len(effect.slow_sd) not in (0, n) or \
                len(effect.slow_mixing) not in (0, n * n) or effect.slow_time_constant <= 0 \
                or list(effect.levels) != sorted(effect.levels):
            raise ValueError('empirical_noise needs sorted levels, one spread per sensor and '
                             'level, n x n mixings, one slow_sd per sensor and '
                             'slow_time_constant > 0')
        if not all(np.all(np.isfinite(np.asarray(v, float))) for v in (
                effect.levels, effect.spread, effect.mixing, effect.slow_sd,
                effect.slow_mixing)):
            raise ValueError('empirical_noise: values must be finite')
    if effect.name == 'intensity_dependent_noise' and (
            effect.direction not in ('dark', 'bright') or effect.constant < 0 or
            effect.scale <= 0 or effect.exponent < -1):
        raise ValueError(f"intensity_dependent_noise needs direction 'dark' or 'bright', "
                         f"constant >= 0, scale > 0, exponent >= -1, got {parameters(effect)}")
    if effect.name == 'temporal_drift' and effect.time_constant <= 0:
        raise ValueError(f'temporal_drift time_constant must be > 0, got '
                         f'{effect.time_constant}')
    if effect.name == 'sensor_gain_offset' and not \
            len(effect.sensors) == len(effect.gains) == len(effect.offsets):
        raise ValueError('sensor_gain_offset needs one gain and one offset per sensor')


def _plain(value):
    if isinstance(value, (tuple, list)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _tuple(value):
    if isinstance(value, list):
        return tuple(_tuple(v) for v in value)
    return value


def dumps(effects) -> str:
    """The simulator's ``effects`` parameter: a JSON list ('' for none)."""
    return json.dumps([to_dict(e) for e in effects]) if effects else ''


def loads(text: str) -> tuple:
    if not text.strip():
        return ()
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f'effects must be a JSON list of effects, got {text[:60]!r} '
                         f'({exc.msg})') from None
    except RecursionError:
        raise ValueError('effects: JSON nested too deeply') from None
    if not isinstance(data, list):
        raise ValueError(f'effects must be a JSON list, got {type(data).__name__}')
    try:
        return tuple(from_dict(d) for d in data)
    except (TypeError, RecursionError) as exc:   # a field of the wrong type
        raise ValueError(f'effects: a field has the wrong type ({exc})') from None
