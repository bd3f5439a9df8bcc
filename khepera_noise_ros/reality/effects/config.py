"""The emulated robot's effects: settings, validation, the YAML format, "the real robot".

The processes that carry the effects out are in ``processes``.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ...core.khepera import DARK, SENSORS
from ...files import atomic_write_text

FORMAT = 'khepera-noise-effects/1'
EFFECTS = ('correlated_noise', 'intensity_dependent_noise', 'sensor_gain_offset',
           'temporal_drift', 'actuator_turn_error', 'sensor_latency', 'saturation_quantization')
ALL_SENSORS = tuple(range(SENSORS))

# Layout of one robot's block of normal draws per sample.
SENSOR_DRAWS = slice(0, 8)       # independent sensor noise
GROUP_DRAWS = slice(8, 16)       # correlated noise, one per group
FLICKER_DRAW = 16                # the room's flicker
DRIFT_DRAWS = slice(17, 25)      # drift innovations, one per sensor (the first if shared)
DRAWS = 25


# --- configuration -------------------------------------------------------------------

@dataclass(frozen=True)
class CorrelatedNoise:
    """White noise shared within each group: sd = strength x the group's mean reading."""

    enabled: bool = False
    strength: float = 0.01
    location: tuple = ((0, 1, 2), (3, 4, 5), (6, 7))


@dataclass(frozen=True)
class IntensityDependentNoise:
    """The room's flicker, one draw for all ``location`` sensors per sample.

    A sensor reading r moves by z * strength * r * (r / 525) ** exponent: the
    darker the reading the larger, so darker conditions are more correlated and
    span a wider range (section 2 of the paper).
    """

    enabled: bool = False
    strength: float = 0.03
    exponent: float = 2.0
    location: tuple = ALL_SENSORS


@dataclass(frozen=True)
class SensorGainOffset:
    """Per-sensor calibration: reading = 525 - gain * (525 - ideal) + offset.

    Gains are 1 + strength * N(0, 1) and offsets offset_sd * N(0, 1), drawn from
    ``unit_seed`` (the unit, not the run, fixes them), unless ``gains`` /
    ``offsets`` give all eight values.  ``per_robot``: each emulated robot is a
    unit of its own; otherwise every robot is the same unit (the paper had one).
    """

    enabled: bool = False
    strength: float = 0.05
    offset_sd: float = 5.0
    unit_seed: int = 1
    per_robot: bool = False
    gains: tuple | None = None
    offsets: tuple | None = None
    location: tuple = ALL_SENSORS


@dataclass(frozen=True)
class TemporalDrift:
    """Slow AR(1) wander of the sensors' gain: stationary sd ``strength`` (a fraction),
    correlation time ``time_constant`` samples; ``shared`` gives one wander for all."""

    enabled: bool = False
    strength: float = 0.01
    time_constant: float = 50.0
    shared: bool = False
    location: tuple = ALL_SENSORS


@dataclass(frozen=True)
class ActuatorTurnError:
    """A commanded turn of x degrees rotates y * scale * (1 +- asymmetry) + strength * |y| *
    N(0, 1) degrees, where y is x less ``dead_band`` degrees toward zero (the motors' static
    friction: a smaller turn does not start the wheels); + for a turn to the right, - to
    the left (the two motors differ, so the robot turns further one way than the other)."""

    enabled: bool = False
    strength: float = 0.1
    scale: float = 1.0
    asymmetry: float = 0.0
    dead_band: float = 0.0
    location: None = None


@dataclass(frozen=True)
class SensorLatency:
    """The ``location`` sensors report what they measured ``strength`` samples ago.

    ``fraction`` (0..1) of a sample is the part of the last turn a measurement still
    sees: the sensor integrates its light over a window that overlaps the end of the
    turn, so it receives fraction x the light before the turn + (1 - fraction) x the
    light after it.
    """

    enabled: bool = False
    strength: int = 1
    fraction: float = 0.0
    location: tuple = ALL_SENSORS


@dataclass(frozen=True)
class SaturationQuantization:
    """Readings rounded to multiples of ``strength``, then clipped to [low, high]."""

    enabled: bool = False
    strength: float = 4.0
    low: float = 0.0
    high: float = DARK
    location: tuple = ALL_SENSORS


EFFECT_TYPES = dict(zip(EFFECTS, (CorrelatedNoise, IntensityDependentNoise, SensorGainOffset,
                                  TemporalDrift, ActuatorTurnError, SensorLatency,
                                  SaturationQuantization)))


@dataclass(frozen=True)
class EffectsConfig:
    """What the emulated robot's world does beyond the ideal light response.

    ``sensor_noise`` is the fraction of each reading a sensor's own noise may
    reach (uniform, the paper's independent noise); it is physics rather than
    an effect and stays on in ``none()``.
    """

    sensor_noise: float = 0.02
    correlated_noise: CorrelatedNoise = field(default_factory=CorrelatedNoise)
    intensity_dependent_noise: IntensityDependentNoise = field(
        default_factory=IntensityDependentNoise)
    sensor_gain_offset: SensorGainOffset = field(default_factory=SensorGainOffset)
    temporal_drift: TemporalDrift = field(default_factory=TemporalDrift)
    actuator_turn_error: ActuatorTurnError = field(default_factory=ActuatorTurnError)
    sensor_latency: SensorLatency = field(default_factory=SensorLatency)
    saturation_quantization: SaturationQuantization = field(
        default_factory=SaturationQuantization)

    def __post_init__(self):
        _number('sensor_noise', self.sensor_noise, 0.0, 1.0)
        for name in EFFECTS:
            effect = getattr(self, name)
            if not isinstance(effect, EFFECT_TYPES[name]):
                raise ValueError(f'effects.{name} must be a {EFFECT_TYPES[name].__name__}, '
                                 f'got {effect!r}')
            object.__setattr__(self, name, _checked(name, effect))

    @classmethod
    def none(cls, sensor_noise: float = 0.02) -> 'EffectsConfig':
        """No effect at all: only each sensor's independent noise, like the simulator's
        independent model at the same level."""
        return cls(sensor_noise=sensor_noise)

    @classmethod
    def real_robot(cls) -> 'EffectsConfig':
        """The emulator's default: the robot that stands in for the paper's Khepera."""
        return REAL_ROBOT

    @classmethod
    def real_robot_v1(cls) -> 'EffectsConfig':
        """The default before issue 27 (``base: real_robot_v1``), for earlier figures."""
        return REAL_ROBOT_V1

    @property
    def enabled(self) -> tuple[str, ...]:
        return tuple(name for name in EFFECTS if getattr(self, name).enabled)

    def replace(self, **effects) -> 'EffectsConfig':
        """A copy with some effects replaced; a dict updates that effect's fields."""
        changes = {}
        for name, value in effects.items():
            if isinstance(value, dict) and name in EFFECT_TYPES:
                value = _effect_from(name, value, getattr(self, name))
            changes[name] = value
        return dataclasses.replace(self, **changes)

    def only(self, *names: str, **changes) -> 'EffectsConfig':
        """Only the named effects switched on (with their fields here), all others off."""
        _known(names)
        off = {n: dataclasses.replace(getattr(self, n), enabled=n in names) for n in EFFECTS}
        return dataclasses.replace(self, **off).replace(**changes)

    def to_dict(self) -> dict:
        return {'format': FORMAT, 'sensor_noise': self.sensor_noise,
                'effects': {name: _plain(dataclasses.asdict(getattr(self, name)))
                            for name in EFFECTS}}

    @classmethod
    def from_dict(cls, data: dict, source: str = 'effects') -> 'EffectsConfig':
        """Keys a file leaves out keep the values of its ``base`` (real_robot,
        real_robot_v1 or none)."""
        if not isinstance(data, dict):
            raise ValueError(f'{source}: expected a mapping, got {type(data).__name__}')
        unknown = set(data) - {'format', 'base', 'sensor_noise', 'effects'}
        if unknown:
            raise ValueError(f'{source}: unknown key(s) {sorted(unknown)}; allowed: format, '
                             f'base, sensor_noise, effects')
        if data.get('format', FORMAT) != FORMAT:
            raise ValueError(f'{source}: format must be {FORMAT!r}, got {data["format"]!r}')
        if str(data.get('base', 'real_robot')) not in BASES:     # str: a list is no key
            raise ValueError(f'{source}: base must be one of {sorted(BASES)}, '
                             f'got {data["base"]!r}')
        config = BASES[data.get('base', 'real_robot')]
        effects = data.get('effects') or {}
        if not isinstance(effects, dict):
            raise ValueError(f'{source}: effects must be a mapping of effect names, '
                             f'got {effects!r}')
        try:
            _known(effects)
            changes = {n: _effect_from(n, v, getattr(config, n)) for n, v in effects.items()}
            if 'sensor_noise' in data:
                changes['sensor_noise'] = data['sensor_noise']
            return dataclasses.replace(config, **changes)
        except ValueError as exc:
            raise ValueError(f'{source}: {exc}') from None

    @classmethod
    def load(cls, path) -> 'EffectsConfig':
        path = Path(path)
        with open(path) as f:
            try:
                data = yaml.safe_load(f)
            except yaml.YAMLError as exc:
                raise ValueError(f'{path}: not valid YAML: {" ".join(str(exc).split())}') from None
        return cls.from_dict(data if data is not None else {}, str(path))

    def save(self, path) -> Path:
        path = Path(path)
        atomic_write_text(path, yaml.safe_dump(self.to_dict(), sort_keys=False,
                                               default_flow_style=None))
        return path


def _known(names) -> None:
    unknown = [n for n in names if n not in EFFECT_TYPES]
    if unknown:
        raise ValueError(f'unknown effect(s) {unknown}; effects are {list(EFFECTS)}')


def _plain(value):
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (tuple, list)):
        return [_plain(v) for v in value]
    return value


def _effect_from(name: str, values: Any, base):
    if not isinstance(values, dict):
        raise ValueError(f'effects.{name} must be a mapping of its fields, got {values!r}')
    allowed = [f.name for f in dataclasses.fields(base)]
    unknown = sorted(set(values) - set(allowed))
    if unknown:
        raise ValueError(f'effects.{name}: unknown field(s) {unknown}; allowed: {allowed}')
    return dataclasses.replace(base, **values)


# --- validation ----------------------------------------------------------------------

def _number(key: str, value, low: float, high: float, integer: bool = False) -> None:
    types = (int, np.integer) if integer else (int, float, np.integer, np.floating)
    if isinstance(value, bool) or not isinstance(value, types) or not low <= value <= high \
            or not np.isfinite(float(value)):     # range first: a huge int is no float
        what = 'an integer' if integer else 'a number'
        raise ValueError(f'{key} must be {what} in [{low:g}, {high:g}], got {value!r}')


def _sensors(key: str, value) -> tuple:
    if not isinstance(value, (list, tuple)) or not value or \
            not all(isinstance(s, (int, np.integer)) and not isinstance(s, bool)
                    and 0 <= s < SENSORS for s in value) or len(set(value)) != len(value):
        raise ValueError(f'{key} must be a non-empty list of distinct sensors 0..7, '
                         f'got {value!r}')
    return tuple(int(s) for s in value)


def _groups(key: str, value) -> tuple:
    if not isinstance(value, (list, tuple)) or not value:
        raise ValueError(f'{key} must be a list of sensor groups, got {value!r}')
    groups = tuple(_sensors(f'{key}[{i}]', g) for i, g in enumerate(value))
    flat = [s for g in groups for s in g]
    if len(flat) != len(set(flat)):
        raise ValueError(f'{key}: groups must not share sensors, got {value!r}')
    return groups


def _eight(key: str, value, low: float, high: float):
    if value is None:
        return None
    if not isinstance(value, (list, tuple)) or len(value) != SENSORS:
        raise ValueError(f'{key} must be null or a list of {SENSORS} numbers, got {value!r}')
    for i, v in enumerate(value):
        _number(f'{key}[{i}]', v, low, high)
    return tuple(float(v) for v in value)


def _flag(key: str, value) -> None:
    if not isinstance(value, bool):
        raise ValueError(f'{key} must be true or false, got {value!r}')


def _checked(name: str, e):
    """The effect with its location normalised, or a ValueError naming the bad field."""
    key = f'effects.{name}'
    _flag(f'{key}.enabled', e.enabled)
    changes: dict[str, Any] = {}
    if isinstance(e, CorrelatedNoise):
        _number(f'{key}.strength', e.strength, 0.0, 1.0)
        changes['location'] = _groups(f'{key}.location', e.location)
    elif isinstance(e, IntensityDependentNoise):
        _number(f'{key}.strength', e.strength, 0.0, 1.0)
        _number(f'{key}.exponent', e.exponent, 0.0, 10.0)
    elif isinstance(e, SensorGainOffset):
        _number(f'{key}.strength', e.strength, 0.0, 0.5)
        _number(f'{key}.offset_sd', e.offset_sd, 0.0, DARK)
        _number(f'{key}.unit_seed', e.unit_seed, 0, 2 ** 63 - 1, integer=True)
        _flag(f'{key}.per_robot', e.per_robot)
        changes['gains'] = _eight(f'{key}.gains', e.gains, 0.0, 10.0)
        changes['offsets'] = _eight(f'{key}.offsets', e.offsets, -DARK, DARK)
    elif isinstance(e, TemporalDrift):
        _number(f'{key}.strength', e.strength, 0.0, 1.0)
        _number(f'{key}.time_constant', e.time_constant, 1.0, 1e9)
        _flag(f'{key}.shared', e.shared)
    elif isinstance(e, ActuatorTurnError):
        _number(f'{key}.strength', e.strength, 0.0, 1.0)
        _number(f'{key}.scale', e.scale, 0.0, 2.0)
        _number(f'{key}.asymmetry', e.asymmetry, -0.9, 0.9)
        _number(f'{key}.dead_band', e.dead_band, 0.0, 180.0)
        if e.location is not None:
            raise ValueError(f'{key}.location must be null (the turn has no location), '
                             f'got {e.location!r}')
    elif isinstance(e, SensorLatency):
        _number(f'{key}.strength', e.strength, 0, 1000, integer=True)
        _number(f'{key}.fraction', e.fraction, 0.0, 1.0)
    elif isinstance(e, SaturationQuantization):
        _number(f'{key}.strength', e.strength, 1.0, DARK)
        _number(f'{key}.low', e.low, 0.0, DARK)
        _number(f'{key}.high', e.high, 0.0, DARK)
        if e.low >= e.high:
            raise ValueError(f'{key}: low must be below high, got low={e.low!r}, '
                             f'high={e.high!r}')
    if e.location is not None and 'location' not in changes:
        changes['location'] = _sensors(f'{key}.location', e.location)
    return dataclasses.replace(e, **changes) if changes else e


# The default robot before issue 27 (config/emulator_v1.yaml is a copy): a whole step of
# latency and a 10% gain spread; it opens a drop that training on it cannot recover.
REAL_ROBOT_V1 = EffectsConfig(
    sensor_noise=0.01,
    correlated_noise=CorrelatedNoise(enabled=True, strength=0.003,
                                     location=((0, 1, 2), (3, 4, 5), (6, 7))),
    intensity_dependent_noise=IntensityDependentNoise(enabled=True, strength=0.06,
                                                      exponent=2.0),
    sensor_gain_offset=SensorGainOffset(enabled=True, strength=0.10, offset_sd=10.0),
    temporal_drift=TemporalDrift(enabled=True, strength=0.004, time_constant=50.0),
    actuator_turn_error=ActuatorTurnError(enabled=True, strength=0.1, scale=0.92),
    sensor_latency=SensorLatency(enabled=True, strength=1),
)
# The robot that stands in for the paper's Khepera (config/emulator.yaml is a copy): the
# same room (flicker, drift and group noise of section 2), a unit's calibration, a quarter
# of a step of latency, and wheels with a dead band and unequal motors (docs/calibration.md).
REAL_ROBOT = dataclasses.replace(
    REAL_ROBOT_V1,
    sensor_gain_offset=SensorGainOffset(enabled=True, strength=0.05, offset_sd=5.0),
    actuator_turn_error=ActuatorTurnError(enabled=True, strength=0.1, scale=0.92,
                                          asymmetry=0.3, dead_band=3.0),
    sensor_latency=SensorLatency(enabled=True, strength=0, fraction=0.25),
)
BASES = {'real_robot': REAL_ROBOT, 'real_robot_v1': REAL_ROBOT_V1,
         'none': EffectsConfig.none()}
