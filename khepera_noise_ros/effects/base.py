"""The effect mechanism: what every simulator-side effect declares, and the checks on it.

An effect is a frozen dataclass whose fields are its parameters, each declared once with
``param`` (a description and its constraints, as the nodes' ``Spec`` rows declare node
parameters).  ``Effect.__post_init__`` checks every field against its declaration, so an
effect that exists is valid and the error names the field and what is allowed.  An
effect names the ``Stage`` it acts on, simulates a batch of robots step by step
(``start``) or a whole run at once (``over_time``: the same numbers, which the contract
test checks), fits itself to real recordings through the ``Evidence`` the diagnosis
gives it (``fit``), and travels as a dict (``to_dict``/``from_dict``).
"""
from __future__ import annotations

import dataclasses
import enum
import math
from dataclasses import dataclass
from typing import Any, Callable, ClassVar, NamedTuple, Protocol, Sequence, TypeVar

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]
Step = Callable[[Array], Array]      # one sample: (channels, robots) levels, or (robots,) turns
T = TypeVar('T')
E = TypeVar('E', bound='Effect')


class Stage(enum.Enum):
    """Where in the loop an effect acts (Gymnasium's wrappers: one stage each)."""

    LIGHT = 'light'          # the light a sensor sees, before the model's noise
    READING = 'reading'      # the noisy reading: the sensor's timing and its converter
    ACTUATOR = 'turn'        # a commanded rotation, in degrees


@dataclass(frozen=True)
class Param:
    """One parameter's declaration: what it is and which values are allowed."""

    doc: str
    kind: str                            # float, int, bool, choice, sensors, groups, floats
    low: float | None = None             # inclusive bounds (each value, for floats)
    high: float | None = None
    above: float | None = None           # strict lower bound
    choices: tuple[str, ...] = ()
    per_sensor: bool = False             # one value per sensor of the location
    ascending: bool = False

    def reason(self, value: Any) -> str:
        """'' if ``value`` is allowed, else what is wrong with it."""
        checks: dict[str, Callable[[Any], str]] = {
            'float': self._number, 'int': self._integer, 'bool': _boolean,
            'choice': self._choice, 'sensors': _sensors, 'groups': _groups,
            'floats': self._numbers}
        return checks[self.kind](value)

    def allowed(self) -> str:
        """The allowed values in words (for errors and the effect catalogue)."""
        if self.kind == 'choice':
            return 'one of ' + ', '.join(repr(c) for c in self.choices)
        if self.kind in ('sensors', 'groups', 'bool'):
            return {'sensors': 'sensor indices >= 0', 'groups': 'lists of sensor indices >= 0',
                    'bool': 'true or false'}[self.kind]
        bounds = [f'> {self.above:g}' if self.above is not None else '',
                  f'>= {self.low:g}' if self.low is not None else '',
                  f'<= {self.high:g}' if self.high is not None else '']
        what = {'float': 'a finite number', 'int': 'an integer',
                'floats': 'a list of finite numbers'}[self.kind]
        extra = [b for b in bounds if b] + (['one per sensor'] if self.per_sensor else []) \
            + (['ascending'] if self.ascending else [])
        return what + (' ' + ', '.join(extra) if extra else '')

    def _bounds(self, x: float) -> bool:
        return (self.low is None or x >= self.low) and (self.high is None or x <= self.high) \
            and (self.above is None or x > self.above)

    def _number(self, value: Any) -> str:
        ok = _is_number(value) and math.isfinite(value) and self._bounds(float(value))
        return '' if ok else f'must be {self.allowed()}'

    def _integer(self, value: Any) -> str:
        ok = isinstance(value, (int, np.integer)) and not isinstance(value, bool) \
            and self._bounds(float(value))
        return '' if ok else f'must be {self.allowed()}'

    def _choice(self, value: Any) -> str:
        return '' if value in self.choices else f'must be {self.allowed()}'

    def _numbers(self, value: Any) -> str:
        ok = isinstance(value, tuple) and all(
            _is_number(v) and math.isfinite(v) and self._bounds(float(v)) for v in value) \
            and (not self.ascending or list(value) == sorted(value))
        return '' if ok else f'must be {self.allowed()}'


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def _boolean(value: Any) -> str:
    return '' if isinstance(value, (bool, np.bool_)) else 'must be true or false'


def _sensors(value: Any) -> str:
    ok = isinstance(value, tuple) and all(
        isinstance(s, (int, np.integer)) and not isinstance(s, bool) and s >= 0 for s in value)
    return '' if ok else 'must be sensor indices >= 0'


def _groups(value: Any) -> str:
    ok = isinstance(value, tuple) and all(_sensors(g) == '' and g for g in value)
    return '' if ok else 'must be non-empty lists of sensor indices >= 0'


def param(default: T, doc: str, kind: str | None = None, **constraints: Any) -> T:
    """A dataclass field that is a declared parameter (its kind guessed from the default)."""
    if kind is None:
        kind = {bool: 'bool', int: 'int', float: 'float', str: 'choice'}[type(default)]
    spec = Param(doc, kind, **constraints)
    if spec.reason(default):
        raise TypeError(f'default {default!r} of a {kind} parameter: {spec.reason(default)}')
    return dataclasses.field(default=default, metadata={'param': spec})  # type: ignore[no-any-return]


@dataclass(frozen=True)
class Effect:
    """An unmodelled effect the simulator can add to the paper's model (see the module)."""

    name: ClassVar[str]
    stage: ClassVar[Stage]
    free: ClassVar[int]       # free parameters beyond the location, for the parsimony rule
    summary: ClassVar[str]    # one line for the effect catalogue

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            spec = f.metadata['param']
            value = getattr(self, f.name)
            why = spec.reason(value)
            if not why and spec.per_sensor and len(value) != len(self.sensors):
                why = f'needs one value per sensor ({len(self.sensors)}), got {len(value)}'
            if why:
                raise ValueError(f'{self.name}: {f.name} {why}, got {_plain(value)!r}')
        why = self.inconsistency()
        if why:
            raise ValueError(f'{self.name}: {why}, got {self.parameters()}')

    def inconsistency(self) -> str:
        """What is wrong between fields that are each allowed ('' if nothing)."""
        return ''

    @classmethod
    def params(cls) -> dict[str, Param]:
        """The declared parameters, in field order."""
        return {f.name: f.metadata['param'] for f in dataclasses.fields(cls)}

    @property
    def sensors(self) -> tuple[int, ...]:
        """The sensors it acts on (none for an actuator effect)."""
        return ()

    @property
    def location(self) -> list[Any]:
        """Where it acts, as diagnosis.json reports it."""
        return list(self.sensors)

    def start(self, robots: int, channels: int, rng: np.random.Generator) -> Step:
        """A fresh state for ``robots`` episodes: a function of one sample."""
        raise NotImplementedError

    def over_time(self, level: Array, rng: np.random.Generator) -> Array:
        """``start`` over (samples, channels, robots) levels at once (effects override it
        with a faster path that gives the same numbers)."""
        step = self.start(level.shape[2], level.shape[1], rng)
        return np.stack([step(level[t]) for t in range(level.shape[0])])

    @classmethod
    def fit(cls: type[E], evidence: Evidence) -> Candidate:
        """Locate and fit this effect on the evidence of real recordings."""
        raise NotImplementedError

    def parameters(self) -> dict[str, Any]:
        """The fields as plain JSON values, without the location."""
        return {k: v for k, v in self.to_dict().items() if k not in ('name', 'sensors', 'groups')}

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {'name': self.name}
        out.update({f.name: _plain(getattr(self, f.name)) for f in dataclasses.fields(self)})
        return out

    @classmethod
    def from_fields(cls: type[E], data: dict[str, Any]) -> E:
        """The effect from its fields (lists become tuples); a ValueError names what is wrong."""
        allowed = set(cls.params())
        unknown = sorted(set(data) - allowed - {'name'})
        if unknown:
            raise ValueError(f'effect {cls.name}: unknown field(s) {unknown}; allowed: '
                             f'{sorted(allowed)}')
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
    """What a fitter returns: the fitted effect, or None and why not."""

    name: str
    effect: Effect | None
    note: str
    given: list[Effect] | None = None   # the chosen effects as refitted with it


class Evidence(Protocol):
    """The real recordings against the simulator (with the effects ``given`` already)."""

    @property
    def channels(self) -> list[int]: ...
    @property
    def kinds(self) -> frozenset[str]: ...
    @property
    def given(self) -> tuple[Effect, ...]: ...
    @property
    def observed_base(self) -> bool: ...
    @property
    def samples(self) -> int: ...

    def rows(self, family: str) -> list[Row]:
        """The comparison's statistics of ``family`` (none if it has none)."""
    def families(self, part: str | None = None) -> frozenset[str]:
        """The families of the real statistics (of one part of them)."""
    def objective(self, effects: Sequence[Effect], kinds: tuple[str, ...] | None = None,
                  families: frozenset[str] | None = None, limits: bool = False) -> float:
        """The discrepancy with ``effects`` added (common random numbers)."""
    def group_evidence(self, part: str) -> Array:
        """(C, C) z that each pair's 'fast' or 'slow' noise is shared beyond the simulator's."""
    def group_null(self, part: str) -> Array:
        """(draws, C, C) the same z of simulated stand-ins for the real data against the
        simulator: the null a group search's stopping rule is checked against."""
    def own_wander(self) -> dict[int, dict[str, Any]]:
        """Sensors whose own part wanders more than simulated: {sensor: {z, sd, acf}}."""
    def shared_change(self) -> dict[str, Any] | None:
        """A change over time shared by the sensors: {significant, sd, ...} or None."""
    def steady_rows(self, rows: list[Row], change: dict[str, Any]) -> list[Row]:
        """Level rows with the shared change taken out of the real readings."""
    def spread_cells(self, sensors: Sequence[int],
                     closed_loop: bool = False) -> list[tuple[float, float]]:
        """[(light level, real minus simulated variance)] of the sensors' noise."""
    def converter(self) -> dict[str, Any]:
        """The value distribution against the simulator's: limits, lattices, dropouts."""
    def rescaled_dropout(self, effect: Effect, sensors: Sequence[int]) -> Effect:
        """``effect`` with its dropout rate scaled to the share of dropouts seen."""
    def delayed_sensors(self) -> tuple[int, ...]:
        """Sensors a latency may act on, from tracked headings (none without)."""
    def stationary_runs(self, simulated: bool) -> list[Array]:
        """Each stationary run's readings (samples, channels), real or simulated."""



def rows(sensors: tuple[int, ...], channels: int) -> list[int]:
    """The sensors as row indices; a ValueError if one lies beyond the data's channels."""
    bad = [s for s in sensors if not 0 <= s < channels]
    if bad:
        raise ValueError(f'effect names sensors {bad}; the data has channels 0..{channels - 1}')
    return list(sensors)


def columns(sensors: tuple[int, ...], channels: int) -> slice | list[int]:
    """``rows`` as an index that gives a view where the effect acts on every channel."""
    located = rows(sensors, channels)
    return slice(None) if located == list(range(channels)) else located


def held(f: Callable[[Array], Array], x: Array) -> Array:
    """``f(x)`` of an elementwise ``f`` over (samples, ...) ``x``, computed only at the
    samples where ``x`` changes (a stationary light holds for a whole run): the same values."""
    if x.shape[0] < 2:
        return f(x)
    new = np.flatnonzero(np.r_[True, (x[1:] != x[:-1]).reshape(x.shape[0] - 1, -1).any(axis=1)])
    if new.size > x.shape[0] // 4:
        return f(x)
    return np.repeat(f(x[new]), np.diff(np.r_[new, x.shape[0]]), axis=0)


def ar1(z: Array, a: float) -> Array:
    """The AR(1) s[t] = a s[t-1] + z[t] along the first axis, s[-1] = 0 (a filter)."""
    from scipy.signal import lfilter
    out: Array = lfilter([1.0], [1.0, -a], z, axis=0)
    return out


def _plain(value: Any) -> Any:
    if isinstance(value, (tuple, list)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _tuple(value: Any) -> Any:
    if isinstance(value, list):
        return tuple(_tuple(v) for v in value)
    return value
