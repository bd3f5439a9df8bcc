"""What the effects' fitters share: thresholds, searches and small statistics."""
from __future__ import annotations

import math
from typing import Any, Callable, Iterable, Sequence, TypeVar

import numpy as np
from scipy import stats as sps

from .base import Array, Effect, Evidence, Row

Z_DETECT = 4.0          # a fingerprint statistic must lie this many standard errors out
E = TypeVar('E', bound=Effect)
ALPHA = 0.01            # family-wise level of the fitters' tests (Holm)
STATIONARY, CLOSED_LOOP = 'stationary', 'closed_loop'
TOL = 0.1               # a lattice measured in readings of another unit: a tenth of a step


def present(evidence: Evidence, kinds: tuple[str, ...]) -> tuple[str, ...] | None:
    """``kinds`` if the recordings have some of them, else None (all of them)."""
    return kinds if set(kinds) & evidence.kinds else None


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


def refine(evidence: Evidence, make: Callable[[float], E], start: float,
           evaluations: int = 7) -> E:
    """``make(x)`` with x refined on a log scale within a factor 3 of ``start``."""
    start = float(np.clip(start, 1e-5, 1e3)) if np.isfinite(start) else 0.01
    kinds = present(evidence, (STATIONARY,))
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


def by_sensor(rows: list[Row]) -> dict[int, list[Row]]:
    """A family's rows by their (first) sensor, in sensor order, each in its own order."""
    out: dict[int, list[Row]] = {}
    for r in sorted(rows, key=lambda r: r.key.sensors[0]):
        out.setdefault(r.key.sensors[0], []).append(r)
    return out


def significant(sensors: Iterable[int], p: Sequence[float]) -> list[int]:
    """The sensors whose p-values, Holm-adjusted, lie below ``ALPHA``."""
    return [s for s, q in zip(sensors, holm(np.asarray(p, np.float64))) if q < ALPHA]


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


def line_p(real: Array, sim: Array, se: Array) -> tuple[Array, float]:
    """The weighted line from the model's levels ``sim`` to the ``real`` ones (an offset alone
    where ``sim`` hardly varies) and the chi-square p-value of its residuals."""
    if np.ptp(sim) < 1:
        line: Array = sim + float(np.average(real - sim, weights=se ** -2))
        dof = real.size - 1
    else:
        line = np.asarray(np.polyval(np.polyfit(sim, real, 1, w=1 / se), sim), np.float64)
        dof = real.size - 2
    return line, float(sps.chi2.sf((((real - line) / se) ** 2).sum(), dof))


def names(sensors: Sequence[int]) -> str:
    return ', '.join(f's{s}' for s in sensors)


def on_grid(x: Array, step: float, origin: float, weight: Any = None) -> float:
    """The share of readings ``x`` (``weight``: each one's count) on the lattice
    origin + k * step: exactly on a lattice of whole numbers, within ``TOL`` steps on one
    measured from readings converted from another unit."""
    if not x.size:
        return 0.0
    off = (x - origin) / step
    tolerance = 0.0 if float(step).is_integer() and float(origin).is_integer() else TOL
    return float(np.average(np.abs(off - np.round(off)) <= tolerance, weights=weight))
