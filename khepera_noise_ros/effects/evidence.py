"""What an effect's fitter sees of the real recordings, and what fitters share.

The diagnosis (``gap``) holds real recordings against the simulator; an effect's
``fit`` reads that comparison through the ``Evidence`` protocol: the statistics of a
family as rows (real, simulated, standard error, z), the discrepancy of the simulator
with trial effects added (``objective``, a deterministic function of its arguments),
and the few measurements that locate an effect (group evidence, own wanders, a shared
change, the converter's value distribution, delayed sensors).  Nothing here knows how
they are computed, so the effects stay below the diagnosis.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, NamedTuple, Protocol, Sequence

import numpy as np

from .base import Array, Effect

Z_DETECT = 4.0          # a fingerprint statistic must lie this many standard errors out
ALPHA = 0.01            # family-wise level of the fitters' tests (Holm)
STATIONARY, CLOSED_LOOP = 'stationary', 'closed_loop'


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
        """The same z of simulated data against the simulator: the null for a stopping rule."""
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


def present(evidence: Evidence, kinds: tuple[str, ...] | None) -> tuple[str, ...] | None:
    """``kinds`` if the recordings have some of them, else None (all of them)."""
    return kinds if kinds is None or set(kinds) & evidence.kinds else None


def golden(f: Callable[[float], float], lo: float, hi: float, evaluations: int) -> float:
    """Minimiser of f on [lo, hi] by golden-section search."""
    g = (math.sqrt(5) - 1) / 2
    a, b = lo, hi
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = f(c), f(d)
    for _ in range(max(0, evaluations - 2)):
        if fc <= fd:
            b, d, fd = d, c, fc
            c = b - g * (b - a)
            fc = f(c)
        else:
            a, c, fc = c, d, fd
            d = a + g * (b - a)
            fd = f(d)
    return c if fc <= fd else d


def refine(evidence: Evidence, make: Callable[[float], Effect], start: float,
           kinds: tuple[str, ...] | None = (STATIONARY,), evaluations: int = 7) -> Effect:
    """``make(x)`` with x refined on a log scale within a factor 3 of ``start``."""
    start = float(np.clip(start, 1e-5, 1e3)) if np.isfinite(start) else 0.01
    kinds = present(evidence, kinds)
    best = golden(lambda u: evidence.objective([make(math.exp(u))], kinds),
                  math.log(start / 3), math.log(start * 3), evaluations)
    return make(round(math.exp(best), 5))


def holm(p: np.ndarray) -> np.ndarray:
    """Holm-adjusted p-values (monotone, at most 1)."""
    n = p.size
    order = np.argsort(p)
    adjusted = np.maximum.accumulate(np.minimum(p[order] * (n - np.arange(n)), 1.0))
    out = np.empty(n)
    out[order] = adjusted
    return out


def by_condition(rows: list[Row]) -> dict[str | None, dict[int, tuple[float, float]]]:
    """{condition: {sensor: (rms real, rms simulated)}} over a family's cells."""
    acc: dict[str | None, dict[int, list[tuple[float, float]]]] = {}
    for r in rows:
        acc.setdefault(r.key.condition, {}).setdefault(r.key.sensors[0], []).append(
            (r.real, r.sim))
    return {cond: {s: (_rms([a for a, _ in v]), _rms([b for _, b in v])) for s, v in by.items()}
            for cond, by in acc.items()}


def _rms(v: list[float]) -> float:
    return float(np.sqrt(np.mean(np.square(v))))


def names(sensors: Sequence[int]) -> str:
    return ', '.join(f's{s}' for s in sensors)
