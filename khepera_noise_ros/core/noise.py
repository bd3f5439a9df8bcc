"""The paper's sensor noise: getnoise, the independent and combination models.

``getnoise(v, p)`` returns an integer in [-p*v, p*v] as the paper's C code
does (truncation toward zero).  The combination model adds one shared
*dependent* draw per dependence group, scaled by the group's average base
value, to an *independent* draw per sensor:

    dnoise = getnoise(groupavg, d%)
    s(n)   = base(n) + dnoise + getnoise(base(n), i%)

Draws arrive as 16-bit integers (see ``streams``) so that a uniform and a
normal model consume the same randomness.

``rounding`` says where the reading becomes an integer: 'level' (the paper's:
integer noise added to an integer light level) or 'reading' (real noise added to
the unrounded light level, rounded and clipped once, as a converter does).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterable, SupportsInt

import numpy as np
import numpy.typing as npt
from scipy.special import ndtri

from .khepera import DARK, SENSORS
from .streams import UNIT

MODELS = ('none', 'independent', 'combination')
DISTRIBUTIONS = ('uniform', 'normal')
ROUNDINGS = ('level', 'reading')
DEFAULT_GROUPS = ((0, 1, 2, 3, 4, 5), (6, 7))
_SQRT3 = np.float32(np.sqrt(3.0))
Groups = tuple[tuple[int, ...], ...]     # dependence groups: sensor indices


def getnoise(v: npt.ArrayLike, p: float, u: np.ndarray | float) -> np.ndarray:
    """The paper's getnoise: ``(int)(2*p*v*realrand() - p*v)`` for draws u in [0, 1]."""
    noise: np.ndarray = np.trunc(2.0 * p * np.asarray(v) * u - p * np.asarray(v))
    return noise


def realrand(draws: np.ndarray) -> np.ndarray:
    """16-bit draws to reals in [0, 1] inclusive, like the paper's realrand()."""
    reals: np.ndarray = draws.astype(np.float32) * np.float32(1.0 / UNIT)
    return reals


def gaussian(draws: np.ndarray) -> np.ndarray:
    """16-bit draws to standard normal deviates (inverse CDF at bin centres)."""
    return ndtri((draws.astype(np.float64) + 0.5) / (UNIT + 1.0)).astype(np.float32)


@dataclass(frozen=True)
class NoiseModel:
    """Which noise, how much of each part, over which dependence groups.

    Levels are fractions (0.05 is the paper's 5%).  The independent model uses
    only ``independent``; ``dependent`` and ``groups`` matter only to the
    combination model.  With ``distribution='normal'`` a part of level p has
    standard deviation p*v/sqrt(3), the same spread as the uniform part.
    """

    model: str = 'combination'
    dependent: float = 0.03
    independent: float = 0.02
    groups: Groups = field(default=DEFAULT_GROUPS)
    distribution: str = 'uniform'
    rounding: str = 'level'

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise ValueError(f'noise model must be one of {MODELS}, got {self.model!r}')
        if self.distribution not in DISTRIBUTIONS:
            raise ValueError(f'distribution must be one of {DISTRIBUTIONS}, '
                             f'got {self.distribution!r}')
        if self.rounding not in ROUNDINGS:
            raise ValueError(f'rounding must be one of {ROUNDINGS}, got {self.rounding!r}')
        for name in ('dependent', 'independent'):
            level = getattr(self, name)
            if not isinstance(level, (int, float, np.floating)) or not np.isfinite(level) \
                    or not 0.0 <= level <= 1.0:
                raise ValueError(f'{name} noise level must be a finite fraction in [0, 1], '
                                 f'got {level!r}')
        object.__setattr__(self, 'groups', check_groups(self.groups))

    @classmethod
    def independent_only(cls, level: float, **kw: Any) -> 'NoiseModel':
        """The independent model at ``level``."""
        return cls(model='independent', dependent=0.0, independent=level, **kw)

    @property
    def levels(self) -> tuple[float, float]:
        """(dependent, independent) fractions actually applied."""
        if self.model == 'none':
            return 0.0, 0.0
        if self.model == 'independent':
            return 0.0, self.independent
        return self.dependent, self.independent

    def apply(self, base: np.ndarray, sensor_draws: np.ndarray,
              group_draws: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Noisy readings, clipped to 0..525: the kernel behind ``task.Episodes``.

        Sensor-major, like the stream draws it consumes (one row per stream channel): the
        batch-first (B, SENSORS) readings that ``Episodes`` hands out are a view of this
        result (docs/architecture.md).  With ``rounding='reading'`` the sum is rounded
        here, once.

        Args:
            base: (SENSORS, B) noise-free readings.
            sensor_draws: (SENSORS, B) uint16 draws for the independent parts.
            group_draws: (>= len(groups), B) uint16 draws, one row per dependence group.
            out: where to write; ``out=base`` overwrites the base values.

        Returns:
            (SENSORS, B) float32 readings.
        """
        out = self.added(base, sensor_draws, group_draws, out=out)
        if self.rounding == 'reading':
            np.rint(out, out=out)
        return np.clip(out, 0.0, DARK, out=out)

    def added(self, base: np.ndarray, sensor_draws: np.ndarray,
              group_draws: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """``base`` plus the noise, neither rounded nor clipped (``apply``'s arguments)."""
        d, i = self.levels
        dnoise = None
        if d > 0 and self.groups:   # group averages come from the base, before any noise
            # every group's dependent part in one (groups, B) block: fewer calls
            dnoise = self._part(group_averages(base, self.groups), d,
                                group_draws[:len(self.groups)])
        independent = self._part(base, i, sensor_draws) if i > 0 else None
        out = base.copy() if out is None else out
        if independent is not None:
            out += independent
        if dnoise is not None:
            for members, shared in zip(_indexers(self.groups), dnoise):
                out[members] += shared
        return out

    def _part(self, v: np.ndarray, p: float, draws: np.ndarray) -> np.ndarray:
        """getnoise(v, p) for every element, computed in place in float32 (not truncated
        when the reading is rounded at the end: the noise is the analogue signal's)."""
        if self.distribution == 'uniform':
            x = draws.astype(np.float32)
            x *= np.float32(2.0 * p / UNIT)     # 2*p*realrand() ...
            x -= np.float32(p)                  # ... - p, then times v: 2*p*v*u - p*v
        else:
            x = gaussian(draws)
            x *= np.float32(p) / _SQRT3
        x *= v
        return x if self.rounding == 'reading' else np.trunc(x, out=x)

    def sample(self, base: npt.ArrayLike, rng: np.random.Generator,
               samples: int = 1) -> np.ndarray:
        """Readings of fixed base values, for plots and checks.

        Args:
            base: (C,) noise-free readings.
            rng: the generator to draw from.
            samples: how many readings of each.

        Returns:
            (samples, C) float32 readings.
        """
        base = np.asarray(base, dtype=np.float32)
        if any(max(g) >= base.size for g in self.groups):
            raise ValueError(f'dependence groups {self.groups} name sensors beyond the '
                             f'{base.size} base values given')
        grid = np.repeat(base[:, None], samples, axis=1)
        draws = rng.integers(0, int(UNIT) + 1, size=(base.size + len(self.groups), samples),
                             dtype=np.uint16)
        readings: np.ndarray = self.apply(grid, draws[:base.size], draws[base.size:]).T
        return readings


def check_groups(groups: Iterable[Iterable[SupportsInt]]) -> Groups:
    """Checked dependence groups.

    Args:
        groups: sequences of sensor indices.

    Returns:
        The groups as a tuple of int tuples.

    Raises:
        ValueError: a group empty, naming a sensor outside 0..7, or overlapping another.
    """
    try:
        checked: Groups = tuple(tuple(int(s) for s in g) for g in groups)
    except (TypeError, ValueError):
        raise ValueError(f'dependence groups must be lists of sensor indices, got {groups!r}')
    seen: set[int] = set()
    for g in checked:
        if not g:
            raise ValueError(f'dependence groups must not be empty, got {checked!r}')
        bad = [s for s in g if not 0 <= s < SENSORS]
        if bad:
            raise ValueError(f'dependence group {list(g)} names sensors {bad}; '
                             f'sensors are 0..{SENSORS - 1}')
        overlap = seen.intersection(g)
        if overlap or len(set(g)) != len(g):
            raise ValueError(f'dependence groups must not overlap: sensor(s) '
                             f'{sorted(overlap) or list(g)} appear twice in {checked!r}')
        seen.update(g)
    if len(checked) > SENSORS:
        raise ValueError(f'at most {SENSORS} dependence groups, got {len(checked)}')
    return checked


def group_averages(base: np.ndarray, groups: Groups) -> np.ndarray:
    """(len(groups), ...) float32 average of each group's rows of ``base`` (SENSORS, ...)."""
    out = np.empty((len(groups),) + base.shape[1:], np.result_type(base.dtype, np.float32))
    for g, members in enumerate(_indexers(groups)):
        np.sum(base[members], axis=0, out=out[g])
        out[g] *= np.float32(1.0 / len(groups[g]))
    return out


def _indexers(groups: Groups) -> list[slice | list[int]]:
    """A slice for each run of adjacent sensors (cheap), else an index list."""
    return [slice(g[0], g[-1] + 1) if list(g) == list(range(g[0], g[-1] + 1)) else list(g)
            for g in groups]


def parse_groups(text: str) -> Groups:
    """'0,1,2;3,4,5' -> ((0, 1, 2), (3, 4, 5)); the empty string means no groups."""
    try:
        groups = [[int(s) for s in g.split(',')] for g in text.split(';') if g.strip()]
    except ValueError:
        raise ValueError(f"dependence groups must look like '0,1,2;3,4,5' (sensor indices, "
                         f"',' within a group, ';' between groups), got {text!r}")
    return check_groups(groups)


def format_groups(groups: Iterable[Iterable[int]]) -> str:
    """((0, 1, 2), (3, 4, 5)) -> '0,1,2;3,4,5', as ``parse_groups`` reads it."""
    return ';'.join(','.join(str(s) for s in g) for g in groups)
