"""Real against simulated statistics: z, Holm significance, the discrepancy
(sum of max(|z| - 2, 0)^2), and where the gap lies."""
from __future__ import annotations

import functools
import warnings
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
from numpy.typing import NDArray
from scipy import stats as sps

from ..effects.base import Array, Key, Row
from ..effects.fitting import ALPHA, holm
from .families import FAMILIES, having

MARGIN = 2.0
Z_CAP = 1e3
# Discrepancy of one statistic with no gap, z ~ N(0, 1): the mean and variance of
# max(|z| - 2, 0)^2; what is left of a part is worked on only above mean + 3 sd.
CHANCE_MEAN, CHANCE_VAR, CHANCE_SDS = 0.011537, 0.012703, 3.0


@dataclass
class Stats:
    """Values of many statistics: ``values`` is (R, K), row 0 the full-data estimate."""

    keys: tuple[Key, ...]
    values: Array

    def __post_init__(self) -> None:
        self.keys = tuple(self.keys)

    @property
    def estimate(self) -> Array:
        out: Array = self.values[0]
        return out

    @functools.cached_property
    def variance(self) -> Array:
        """Bootstrap variance of each statistic (0 without replicates)."""
        if self.values.shape[0] < 3:
            return np.zeros(len(self.keys))
        with warnings.catch_warnings():
            warnings.simplefilter('ignore', RuntimeWarning)     # all-NaN columns give NaN
            var: Array = np.nanvar(self.values[1:], axis=0, ddof=1)
        return var

    @functools.cached_property
    def index(self) -> dict[Key, int]:
        return {k: i for i, k in enumerate(self.keys)}

    @staticmethod
    def join(parts: Sequence['Stats']) -> 'Stats':
        if len(parts) == 1:          # no copy of the one
            return parts[0]
        rows = min(p.values.shape[0] for p in parts)
        return Stats(tuple(k for p in parts for k in p.keys),
                     np.concatenate([p.values[:rows] for p in parts], axis=1))


@dataclass
class Comparison:
    keys: list[Key]
    real: Array
    sim: Array
    se: Array
    z: Array
    _families: dict[str, list[Row]] | None = field(default=None, repr=False)

    @property
    def p_holm(self) -> Array:
        out: Array = holm(2.0 * sps.norm.sf(np.abs(self.z)))
        return out

    def significant(self, alpha: float = ALPHA) -> NDArray[np.bool_]:
        out: NDArray[np.bool_] = self.p_holm < alpha
        return out

    @property
    def discrepancy(self) -> float:
        return discrepancy(self.z)

    def select(self, mask: Any) -> 'Comparison':
        keep = np.flatnonzero(mask)
        return Comparison([self.keys[i] for i in keep], self.real[keep], self.sim[keep],
                          self.se[keep], self.z[keep])

    def rows(self, family: str) -> list[Row]:
        """The statistics of ``family`` (the comparison is split by family once)."""
        if self._families is None:
            self._families = {}
            for row in zip(self.keys, self.real, self.sim, self.se, self.z):
                self._families.setdefault(row[0].family, []).append(Row(*row))
        return list(self._families.get(family, ()))

    @functools.cached_property
    def index(self) -> dict[Key, int]:
        return {k: i for i, k in enumerate(self.keys)}

    @functools.cached_property
    def parts(self) -> Array:
        """Each statistic's part (``families.PARTS``)."""
        return np.array([FAMILIES[k.family].part for k in self.keys], dtype=object)

    def part(self, name: str) -> 'Comparison':
        return self.select(self.parts == name)

    def of(self, family: str) -> 'Comparison':
        return self.select([k.family == family for k in self.keys])


def discrepancy(z: Array, margin: float = MARGIN) -> float:
    """sum of max(|z| - margin, 0)^2; margin 0 gives the plain sum of squares."""
    return float((np.clip(np.abs(z) - margin, 0.0, None) ** 2).sum())


def reduction(before: float, after: float) -> float:
    """The share of the discrepancy ``before`` that ``after`` removes (0 with none before)."""
    return 1.0 - after / before if before > 0 else 0.0


def chance(n: int) -> float:
    """The discrepancy ``n`` statistics reach by chance with no gap left (mean + 3 sd)."""
    return float(n * CHANCE_MEAN + CHANCE_SDS * np.sqrt(n * CHANCE_VAR))


def paired_p(before: Array, after: Array, d_prev: float, d_new: float) -> float:
    """One-sided p that ``after`` does not lower the discrepancy: the paired replicate
    differences centred on the estimate's difference."""
    diff = before - after
    diff = diff + (d_prev - d_new) - np.median(diff)
    return float((np.sum(diff <= 0) + 1) / (diff.size + 1))


def replicate_discrepancies(reps: Array, c: Comparison) -> Array:
    """Each real bootstrap replicate's discrepancy against the simulated side of ``c``
    (``reps``: (R, K), a column per key of ``c``)."""
    with np.errstate(divide='ignore', invalid='ignore'):
        z = (reps - c.sim[None]) / c.se[None]
    z = np.nan_to_num(z, nan=0.0, posinf=1e3, neginf=-1e3)
    out: Array = (np.clip(np.abs(z) - MARGIN, 0.0, None) ** 2).sum(axis=1)
    return out


def floors(keys: Sequence[Key]) -> Array:
    """The squared least standard error of each statistic (its family's floor)."""
    return np.array([FAMILIES[k.family].floor for k in keys]) ** 2


def compare(real: Stats, sim: Stats, inflation: Array | None = None) -> Comparison:
    """The statistics both share, their differences standardised; ``inflation`` (aligned
    with ``sim.keys``) scales both variances where the bootstrap understates them."""
    where = sim.index
    ri = np.array([i for i, k in enumerate(real.keys) if k in where], np.int64)
    keys = [real.keys[i] for i in ri]
    si = np.array([where[k] for k in keys], np.int64)
    r, s = real.estimate[ri], sim.estimate[si]
    scale = 1.0 if inflation is None else inflation[si]
    se = np.sqrt((real.variance[ri] + sim.variance[si]) * scale + floors(keys))
    ok = np.flatnonzero(np.isfinite(r) & np.isfinite(s) & np.isfinite(se))
    z = np.clip((r[ok] - s[ok]) / se[ok], -Z_CAP, Z_CAP)
    return Comparison([keys[i] for i in ok], r[ok], s[ok], se[ok], z)


def entries(c: Comparison, limit: int = 40, alpha: float = ALPHA) -> list[dict[str, Any]]:
    """The ``where`` list of diagnosis.json: largest |z| first."""
    order = np.argsort(-np.abs(c.z), kind='stable')[:limit]
    p = c.p_holm
    return [{'statistic': c.keys[i].family, 'sensors': list(c.keys[i].sensors),
             'condition': c.keys[i].condition, 'part': c.keys[i].part,
             'sim': float(c.sim[i]), 'real': float(c.real[i]),
             'significance': float(abs(c.z[i])), 'p_value': float(p[i]),
             'significant': bool(p[i] < alpha)} for i in order]


def localise(c: Comparison, alpha: float = ALPHA) -> dict[str, dict[str, float]]:
    """The shares of the significant discrepancy by family, sensor, pair, condition, part."""
    weight = np.clip(np.abs(c.z) - MARGIN, 0.0, None) ** 2 * c.significant(alpha)
    total = weight.sum()
    out: dict[str, dict[str, float]] = {k: {} for k in ('families', 'sensors', 'pairs',
                                                        'conditions', 'parts')}
    if total <= 0:
        return out
    for key, w in zip(c.keys, weight / total):
        if w <= 0:
            continue
        shares = [('families', key.family, w), ('conditions', key.condition or 'all', w),
                  ('parts', key.part or 'all', w)]
        if len(key.sensors) == 2:
            shares.append(('pairs', '-'.join(f's{s}' for s in key.sensors), w))
        shares += [('sensors', f's{s}', w / len(key.sensors)) for s in key.sensors]
        for table, name, value in shares:
            out[table][name] = out[table].get(name, 0.0) + float(value)
    return {k: dict(sorted(v.items(), key=lambda kv: -kv[1])) for k, v in out.items()}


def test(r: float, n_r: float, s: float, n_s: float) -> tuple[float, float]:
    """(z, standard error of the difference in shares) of ``r`` events in ``n_r`` real
    readings against ``s`` in ``n_s`` simulated: the conditional binomial test of equal
    rates as a normal z; 0 when neither side has any."""
    k = r + s
    d = r / n_r - s / n_s
    se0 = float(np.sqrt(max(k, 1.0) / (n_r + n_s) * (1.0 / n_r + 1.0 / n_s)))
    if k <= 0:
        return 0.0, se0
    f = n_r / (n_r + n_s)
    p = min(1.0, 2.0 * min(sps.binom.sf(r - 1, k, f), sps.binom.cdf(r, k, f)))
    z = float(min(sps.norm.isf(p / 2.0), Z_CAP)) * (1.0 if d >= 0 else -1.0)
    if abs(z) < 1e-9 or abs(d) <= 0:
        return 0.0, se0
    return z, abs(d) / abs(z)


def recount(c: Comparison, real: dict[Key, list[float]],
            sim: dict[Key, list[float]]) -> Comparison:
    """``c`` with the counted statistics judged by ``test``."""
    counted = having('counted')
    rows = [i for i, k in enumerate(c.keys) if k.family in counted and k in real and k in sim
            and real[k][1] > 0 and sim[k][1] > 0]
    if not rows:
        return c
    real_, sim_, se, z = (np.array(v, np.float64) for v in (c.real, c.sim, c.se, c.z))
    for i in rows:
        (r, n_r), (s, n_s) = real[c.keys[i]], sim[c.keys[i]]
        z[i], se[i] = test(r, n_r, s, n_s)
        real_[i], sim_[i] = r / n_r, s / n_s
    return Comparison(c.keys, real_, sim_, se, z)
