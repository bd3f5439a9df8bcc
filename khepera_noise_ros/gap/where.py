"""Where the gap lies: real against simulated statistics, standardised and ranked.

Each statistic's difference is divided by its standard error, the root of the
sum of the two block-bootstrap variances, to give z.  Significance is judged
by Holm's step-down correction over every statistic compared, so the chance
of calling any statistic different when none is stays at ``alpha`` however
many are compared and however they depend on each other.

The *discrepancy* of a comparison is  sum over statistics of max(|z| - 2, 0)^2:
each statistic counts by how far it lies beyond two standard errors, so the
many statistics that agree contribute (almost) nothing, and it is the number
an effect has to shrink.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats as sps

from .statistics import Key, Stats

ALPHA = 0.01
MARGIN = 2.0
Z_CAP = 1e3
# The least standard error a statistic can have: readings are integers, so a level is
# not known better than a uniform error of +-0.5 (sd 0.29), even where it never varies.
# pileup: where a pile is looked for is fixed in the bootstrap, so its error is floored;
# a dropout share: a count; its bootstrap error is Poisson's, floored at 1 in 10,000
FLOORS = {'level': 0.3, 'closed_loop_level': 0.3, 'spread': 0.05, 'pileup': 0.004,
          'turn_size_scatter': 0.03,    # headings in tenths of a degree
          'dropout': 1e-4, 'closed_loop_dropout': 1e-4}
FLOOR = 0.002


@dataclass
class Comparison:
    keys: list[Key]
    real: np.ndarray
    sim: np.ndarray
    se: np.ndarray
    z: np.ndarray

    @property
    def p(self) -> np.ndarray:
        """Two-sided p-values of each difference."""
        return 2.0 * sps.norm.sf(np.abs(self.z))

    @property
    def p_holm(self) -> np.ndarray:
        return holm(self.p)

    def significant(self, alpha: float = ALPHA) -> np.ndarray:
        return self.p_holm < alpha

    @property
    def discrepancy(self) -> float:
        return discrepancy(self.z)

    def select(self, mask) -> 'Comparison':
        keep = np.flatnonzero(mask)
        return Comparison([self.keys[i] for i in keep], self.real[keep], self.sim[keep],
                          self.se[keep], self.z[keep])


def discrepancy(z: np.ndarray, margin: float = MARGIN) -> float:
    """sum of max(|z| - margin, 0)^2; margin 0 gives the plain sum of squares."""
    return float((np.clip(np.abs(z) - margin, 0.0, None) ** 2).sum())


def holm(p: np.ndarray) -> np.ndarray:
    """Holm-adjusted p-values (monotone, at most 1)."""
    n = p.size
    order = np.argsort(p)
    adjusted = np.maximum.accumulate(np.minimum(p[order] * (n - np.arange(n)), 1.0))
    out = np.empty(n)
    out[order] = adjusted
    return out


def compare(real: Stats, sim: Stats, inflation: np.ndarray | None = None) -> Comparison:
    """Line up the statistics both share and standardise their differences.

    ``inflation`` (aligned with ``sim.keys``) scales both bootstrap variances of a
    statistic where the bootstrap is known to understate them.
    """
    where = sim.index()
    pairs = [(i, where[k]) for i, k in enumerate(real.keys) if k in where]
    ri = np.array([p[0] for p in pairs], np.int64)
    si = np.array([p[1] for p in pairs], np.int64)
    r, s = real.estimate[ri], sim.estimate[si]
    scale = 1.0 if inflation is None else inflation[si]
    keys = [real.keys[i] for i in ri]
    se = standard_error((real.variance[ri] + sim.variance[si]) * scale, keys)
    ok = np.isfinite(r) & np.isfinite(s) & np.isfinite(se)
    keep = np.flatnonzero(ok)
    z = np.clip((r[ok] - s[ok]) / se[ok], -Z_CAP, Z_CAP)
    return Comparison([keys[i] for i in keep], r[ok], s[ok], se[ok], z)


def standard_error(variance: np.ndarray, keys: list[Key]) -> np.ndarray:
    """sqrt(variance + floor^2), the floor of each statistic's family (``FLOORS``)."""
    return np.sqrt(variance + squared_floors(keys))


def squared_floors(keys: list[Key]) -> np.ndarray:
    """The squared least standard error of each statistic (its family's ``FLOORS``)."""
    return np.array([FLOORS.get(k.family, FLOOR) for k in keys]) ** 2


def entries(c: Comparison, limit: int = 40, alpha: float = ALPHA) -> list[dict]:
    """The ``where`` list of diagnosis.json: largest |z| first."""
    order = np.argsort(-np.abs(c.z), kind='stable')[:limit]
    p = c.p_holm
    return [{'statistic': c.keys[i].family, 'sensors': list(c.keys[i].sensors),
             'condition': c.keys[i].condition, 'part': c.keys[i].part,
             'sim': float(c.sim[i]), 'real': float(c.real[i]),
             'significance': float(abs(c.z[i])), 'p_value': float(p[i]),
             'significant': bool(p[i] < alpha)} for i in order]


def localise(c: Comparison, alpha: float = ALPHA) -> dict:
    """Which families, sensors, sensor pairs, conditions and parts carry the significant
    discrepancy, each with its share of the discrepancy."""
    sig = c.significant(alpha)
    weight = np.clip(np.abs(c.z) - MARGIN, 0.0, None) ** 2 * sig
    total = weight.sum()
    out: dict = {k: {} for k in ('families', 'sensors', 'pairs', 'conditions', 'parts')}
    if total <= 0:
        return out
    for key, w in zip(c.keys, weight / total):
        if w <= 0:
            continue
        _add(out['families'], key.family, w)
        if len(key.sensors) == 2:
            _add(out['pairs'], '-'.join(f's{s}' for s in key.sensors), w)
        for s in key.sensors:
            _add(out['sensors'], f's{s}', w / len(key.sensors))
        _add(out['conditions'], key.condition or 'all', w)
        _add(out['parts'], key.part or 'all', w)
    return {k: dict(sorted(v.items(), key=lambda kv: -kv[1])) for k, v in out.items()}


def _add(table: dict, name: str, value: float) -> None:
    table[name] = table.get(name, 0.0) + float(value)
