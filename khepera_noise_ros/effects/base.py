"""The effect mechanism: what every simulator-side effect declares, and the checks on it.

An effect is a frozen dataclass whose fields are its parameters, each declared once with
``param`` (a description and the values allowed); constructing one checks every field,
so an effect that exists is valid.  Its class keywords name it and the ``Stage`` it acts
on.  It simulates a batch step by step (``start``) or a whole run at once (``over_time``:
the same numbers; an effect without memory writes ``act`` for both), fits itself through
the ``Evidence`` the diagnosis gives it, and travels as a dict.
"""
from __future__ import annotations

import dataclasses
import enum
import math
from dataclasses import dataclass
from typing import Any, Callable, ClassVar, NamedTuple, Protocol, Sequence, TypeVar

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter

Array = NDArray[np.float64]
AnyArray = NDArray[Any]       # draws (uint16), float32 levels
Step = Callable[[Array], Array]      # one sample: (channels, robots) levels, or (robots,) turns
T = TypeVar('T')
E = TypeVar('E', bound='Effect')


class Stage(enum.Enum):
    """Where in the loop an effect acts (as Gymnasium's wrappers: one stage each)."""

    WORLD = 'world'          # the light at each bearing: the (sensors, tenths) table
    LIGHT = 'light'          # the light a sensor sees, before the model's noise
    READING = 'reading'      # the noisy reading: the sensor's timing and its converter
    ACTUATOR = 'turn'        # a commanded rotation, in degrees


def _number(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) \
        and bool(math.isfinite(v))


def _index(v: Any) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, bool) and bool(v >= 0)


@dataclass(frozen=True)
class Param:
    """One parameter's declaration: what it is and which values are allowed."""

    doc: str
    kind: str                            # float, int, bool, choice, sensors, groups, floats
    low: float | None = None             # inclusive bounds (of each value, for floats)
    high: float | None = None
    above: float | None = None           # a strict lower bound
    choices: tuple[str, ...] = ()
    per_sensor: bool = False             # one value per sensor of the location
    ascending: bool = False

    def allows(self, v: Any) -> bool:
        kind = self.kind
        if kind in ('float', 'int'):
            whole = isinstance(v, (int, np.integer)) and not isinstance(v, bool)
            return (_number(v) if kind == 'float' else whole) and self._within(v)
        if kind == 'floats':
            return isinstance(v, tuple) and all(_number(x) and self._within(x) for x in v) \
                and (not self.ascending or list(v) == sorted(v))
        return {'bool': lambda: isinstance(v, (bool, np.bool_)),
                'choice': lambda: v in self.choices,
                'sensors': lambda: isinstance(v, tuple) and all(_index(s) for s in v),
                'groups': lambda: isinstance(v, tuple) and all(
                    isinstance(g, tuple) and g and all(_index(s) for s in g) for g in v)}[kind]()

    def _within(self, x: float) -> bool:
        return (self.low is None or x >= self.low) and (self.high is None or x <= self.high) \
            and (self.above is None or x > self.above)

    def allowed(self) -> str:
        """The allowed values in words (errors and the effect catalogue)."""
        if self.kind in ('choice', 'sensors', 'groups', 'bool'):
            return {'choice': 'one of ' + ', '.join(repr(c) for c in self.choices),
                    'sensors': 'sensor indices >= 0', 'bool': 'true or false',
                    'groups': 'non-empty lists of sensor indices >= 0'}[self.kind]
        limits = [f'{op} {v:g}' for op, v in (('>', self.above), ('>=', self.low),
                                              ('<=', self.high)) if v is not None]
        limits += ['one per sensor'] * self.per_sensor + ['ascending'] * self.ascending
        what = {'float': 'a finite number', 'int': 'an integer',
                'floats': 'a list of finite numbers'}[self.kind]
        return ' '.join([what] + [', '.join(limits)] * bool(limits))


def param(default: T, doc: str, kind: str | None = None, **allowed: Any) -> T:
    """A dataclass field that is a declared parameter (its kind guessed from the default)."""
    kind = kind or {bool: 'bool', int: 'int', float: 'float', str: 'choice'}[type(default)]
    spec = Param(doc, kind, **allowed)
    if not spec.allows(default):
        raise TypeError(f'default {default!r} of {doc!r} is not {spec.allowed()}')
    return dataclasses.field(default=default, metadata={'param': spec})


@dataclass(frozen=True)
class Effect:
    """An unmodelled effect the simulator can add to the paper's model (see the module)."""

    name: ClassVar[str]
    stage: ClassVar[Stage]
    free: ClassVar[int]       # free parameters beyond the location, for the parsimony rule
    summary: ClassVar[str]    # one line for the effect catalogue
    # a world part: the unmodelled effect that is the part at special values of its
    # parameters (the same stage, fewer free parameters), which the held-out data may prefer
    plain: ClassVar[str | None] = None

    def __init_subclass__(cls, name: str | None = None, stage: Stage | None = None,
                          free: int | None = None, summary: str | None = None,
                          plain: str | None = None) -> None:
        """An effect declares those above as class keywords (or keeps its parent's)."""
        super().__init_subclass__()
        for key, value in dict(name=name, stage=stage, free=free, summary=summary,
                               plain=plain).items():
            if value is not None:
                setattr(cls, key, value)

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            spec, value = f.metadata['param'], getattr(self, f.name)
            why = '' if spec.allows(value) else f'must be {spec.allowed()}'
            if not why and spec.per_sensor and len(value) != len(self.sensors):
                why = f'needs one value per sensor ({len(self.sensors)})'
            if why:
                raise ValueError(f'{self.name}: {f.name} {why}, got {_plain(value)!r}')
        if self.inconsistency():
            raise ValueError(f'{self.name}: {self.inconsistency()}, got {self.parameters()}')

    def inconsistency(self) -> str:
        """What is wrong between fields that are each allowed ('' if nothing)."""
        return ''

    @classmethod
    def params(cls) -> dict[str, Param]:
        return {f.name: f.metadata['param'] for f in dataclasses.fields(cls)}

    @property
    def sensors(self) -> tuple[int, ...]:
        """The sensors it acts on (none for an actuator effect)."""
        return ()

    @property
    def location(self) -> list[Any]:
        return list(self.sensors)

    def start(self, robots: int, channels: int, rng: np.random.Generator) -> Step:
        """A fresh state for ``robots`` episodes: a function of one sample."""
        rows(self.sensors, channels)
        if self.stage is Stage.ACTUATOR:       # a sample: the robots' turns, of any shape
            return lambda deg: self.act(np.reshape(deg, (1, 1, -1)), rng).reshape(np.shape(deg))
        return lambda level: self.act(level[None], rng)[0]

    def over_time(self, level: Array, rng: np.random.Generator) -> Array:
        """``start`` over (samples, channels, robots) at once: the same numbers."""
        return self.act(level, rng)

    def act(self, level: Array, rng: np.random.Generator) -> Array:
        """``over_time`` of an effect without memory, drawing sample by sample (then one
        sample is a step); an actuator's level is the commanded turns, degrees."""
        raise NotImplementedError

    def table(self, table: Array, world: Any) -> Array:
        """A world-stage effect: the (channels, tenths of a degree) light table of
        ``world`` (a ``core.khepera.World``, unrounded) as the robot sees it."""
        raise NotImplementedError

    @classmethod
    def fit(cls, evidence: Evidence) -> Candidate:
        """Locate and fit this effect on the evidence of real recordings."""
        raise NotImplementedError

    @classmethod
    def nothing(cls, why: str) -> Candidate:
        """The fitter's answer when it finds nothing to fit."""
        return Candidate(cls.name, None, why)

    def parameters(self) -> dict[str, Any]:
        """The fields as plain values, without the location."""
        return {k: v for k, v in self.to_dict().items() if k not in ('name', 'sensors', 'groups')}

    def to_dict(self) -> dict[str, Any]:
        return {'name': self.name, **{f.name: _plain(getattr(self, f.name))
                                      for f in dataclasses.fields(self)}}

    @classmethod
    def from_fields(cls: type[E], data: dict[str, Any]) -> E:
        """The effect from its fields (lists as tuples); a ValueError names what is wrong."""
        unknown = sorted(set(data) - set(cls.params()) - {'name'})
        if unknown:
            raise ValueError(f'effect {cls.name}: unknown field(s) {unknown}; allowed: '
                             f'{sorted(cls.params())}')
        return cls(**{k: _tuple(v) for k, v in data.items() if k != 'name'})


class Key(NamedTuple):
    """A statistic's name: its family, sensors, lighting condition and part."""

    family: str
    sensors: tuple[int, ...]
    condition: str | None
    part: str | None


class Row(NamedTuple):
    """One statistic of a comparison, real against simulated."""

    key: Key
    real: float
    sim: float
    se: float
    z: float


@dataclass
class Candidate:
    """A fitter's answer: the fitted effect, or None and why not."""

    name: str
    effect: Effect | None
    note: str
    given: list[Effect] | None = None   # the chosen effects as refitted with it


class Evidence(Protocol):
    """What a fitter sees: real recordings against the simulator with the effects
    ``given`` (``gap.target.TargetEvidence``; docs/diagnosis.md says how each is made)."""

    channels: list[int]
    kinds: frozenset[str]                                    # 'stationary', 'closed_loop'
    given: tuple[Effect, ...]
    observed_base: bool                                      # no light model: no levels
    samples: int

    def rows(self, family: str) -> list[Row]: ...            # a family's statistics
    def families(self, part: str | None = None) -> frozenset[str]: ...      # present ones

    def objective(self, effects: Sequence[Effect], kinds: tuple[str, ...] | None = None,
                  families: frozenset[str] | None = None, limits: bool = False) -> float: ...

    def group_evidence(self, part: str) -> Array: ...  # (C, C) z: 'fast'/'slow' noise shared
    def group_null(self, part: str) -> Array: ...      # (draws, C, C) the same with no gap
    def own_wander(self) -> dict[int, dict[str, Any]]: ...
    def shared_change(self) -> dict[str, Any] | None: ...
    def steady_rows(self, rows: list[Row], change: dict[str, Any]) -> list[Row]: ...

    def spread_cells(self, sensors: Sequence[int],
                     closed_loop: bool = False) -> list[tuple[float, float]]: ...

    def converter(self) -> dict[str, Any]: ...
    def rescaled_dropout(self, effect: Effect, sensors: Sequence[int]) -> Effect: ...
    def delayed_sensors(self) -> tuple[int, ...]: ...
    def stationary_runs(self, simulated: bool) -> list[Array]: ...
    def worlds(self) -> dict[str, Any]: ...            # condition label -> its World
    def turns(self) -> Array: ...      # (n, 2) commanded and executed turns, degrees


def rows(sensors: tuple[int, ...], channels: int) -> list[int]:
    """The sensors as rows; a ValueError if one lies beyond the data's channels."""
    bad = [s for s in sensors if not 0 <= s < channels]
    if bad:
        raise ValueError(f'effect names sensors {bad}; the data has channels 0..{channels - 1}')
    return list(sensors)


def columns(sensors: tuple[int, ...], channels: int) -> slice | list[int]:
    """``rows`` as an index that is a view where the effect acts on every channel."""
    located = rows(sensors, channels)
    return slice(None) if located == list(range(channels)) else located


def replaced(level: Array, cols: slice | list[int], values: Any) -> Array:
    """A copy of ``level`` (a sample's or a run's) with ``values`` on the channels ``cols``."""
    out: Array = level.copy()
    out[..., cols, :] = values
    return out


def held(f: Callable[[Array], Array], x: Array) -> Array:
    """``f(x)`` of an elementwise ``f`` over (samples, ...), computed only where ``x``
    changes (a stationary light holds for a whole run): the same values."""
    if x.shape[0] < 2:
        return f(x)
    new = np.flatnonzero(np.r_[True, (x[1:] != x[:-1]).reshape(x.shape[0] - 1, -1).any(axis=1)])
    if new.size > x.shape[0] // 4:
        return f(x)
    return np.repeat(f(x[new]), np.diff(np.r_[new, x.shape[0]]), axis=0)


def ar1(z: Array, a: float) -> Array:
    """The AR(1) s[t] = a s[t-1] + z[t] along the first axis, s[-1] = 0."""
    return lfilter([1.0], [1.0, -a], z, axis=0)


def _plain(value: Any) -> Any:
    if isinstance(value, (tuple, list)):
        return [_plain(v) for v in value]
    return value.item() if isinstance(value, np.generic) else value


def _tuple(value: Any) -> Any:
    return tuple(_tuple(v) for v in value) if isinstance(value, list) else value
