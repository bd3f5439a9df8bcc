"""``correlated_noise``: fast noise shared within groups of sensors (the paper's dependence
groups, found from the data).

The groups: sensors merged by average linkage of the evidence that their fast noise is
shared beyond the simulator's (a z per pair) while the link exceeds a z of 4 and chance.
The strength: from the excess covariance within the groups, refined by the simulator; a
shared noise of a fixed size in readings (a supply, a converter) is tried as well.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
from scipy import stats as sps

from ..core.khepera import DARK
from .base import Array, Candidate, Effect, Evidence, Stage, param, rows
from .fitting import ALPHA, by_condition, names, refine

THRESHOLD = 4.0


@dataclass(frozen=True)
class CorrelatedNoise(Effect, name='correlated_noise', stage=Stage.LIGHT, free=1,
                      summary='fast noise shared within groups of sensors (dependence groups)'):
    groups: tuple[tuple[int, ...], ...] = param((), 'groups of sensors that share noise', 'groups')
    strength: float = param(0.01, 'sd as a fraction of the group\'s mean level', low=0.0)
    constant: float = param(0.0, 'sd in readings, whatever the level', low=0.0)

    @property
    def sensors(self) -> tuple[int, ...]:
        return tuple(sorted(s for g in self.groups for s in g))

    @property
    def location(self) -> list[Any]:
        return [list(g) for g in self.groups]

    def parameters(self) -> dict[str, Any]:
        return {**super().parameters(), 'groups': self.location}

    def act(self, level: Array, rng: np.random.Generator) -> Array:
        located = [rows(g, level.shape[1]) for g in self.groups]
        out: Array = level.copy()
        z = rng.standard_normal((level.shape[0], len(located), level.shape[2]))
        for g, members in enumerate(located):
            sd = self.strength * level[:, members].mean(axis=1) + self.constant
            out[:, members] += (sd * z[:, g])[:, None]
        return out

    @classmethod
    def fit(cls, evidence: Evidence) -> Candidate:
        found = tuple(tuple(evidence.channels[i] for i in g)
                      for g in groups_of(evidence, evidence.group_evidence('fast')))
        if not found:
            return cls.nothing('no sensors whose noise is more correlated than simulated')
        start = _shared_strength(evidence, found)
        # closed loop only: the spreads give the start
        first = start if evidence.rows('correlation') else _loop_strength(evidence, found) or start
        effect = refine(evidence, lambda s: cls(found, s), first)
        # shared noise of a fixed size in readings, one more form of the same effect
        level = float(np.mean([r.real for r in evidence.rows('level')] or [DARK / 2]))
        fixed = refine(evidence, lambda s: cls(found, 0.0, s), start * level, evaluations=5)
        if evidence.objective([fixed]) < evidence.objective([effect]):
            effect = fixed
        text = ' '.join('{' + names(g) + '}' for g in found)
        return Candidate(cls.name, effect, f'excess correlation clusters into {text}')


def groups_of(evidence: Evidence, z: Array) -> list[list[int]]:
    """Groups (positions in ``evidence.channels``) of the pair evidence ``z``, merged while
    the link exceeds ``THRESHOLD`` and chance: the Bonferroni threshold over the pairs at
    ``ALPHA``, widened by how much wider than N(0, 1) the same evidence is between the
    simulator and itself (a lower threshold let the emulated robot's flicker merge every
    sensor and its drift go unseen)."""
    c = z.shape[0]
    if c < 2 or not (z > THRESHOLD).any():       # no link could count: the null is not needed
        return []
    null = evidence.group_null('fast')
    off = ~np.eye(c, dtype=bool)
    spread = float(np.sqrt(np.mean(null[:, off] ** 2))) if null.size else 1.0
    return cluster(z, max(THRESHOLD,
                          max(1.0, spread) * float(sps.norm.isf(ALPHA / (c * (c - 1) / 2)))))


def cluster(evidence: Array, threshold: float = THRESHOLD) -> list[list[int]]:
    """Groups (lists of row indices, two or more each) of a symmetric evidence matrix:
    average linkage while the mean evidence between two clusters exceeds ``threshold``."""
    clusters = [[i] for i in range(evidence.shape[0])]
    while len(clusters) > 1:
        best, pair = -np.inf, (0, 0)
        for a in range(len(clusters)):
            for b in range(a + 1, len(clusters)):
                link = evidence[np.ix_(clusters[a], clusters[b])].mean()
                if link > best:
                    best, pair = link, (a, b)
        if best <= threshold:
            break
        a, b = pair
        clusters[a] = sorted(clusters[a] + clusters[b])
        del clusters[b]
    return sorted((c for c in clusters if len(c) > 1), key=lambda c: c[0])


def _shared_strength(evidence: Evidence, groups: Sequence[tuple[int, ...]]) -> float:
    """Shared sd as a fraction of the level: the excess covariance within the groups over
    the mean squared level (moments of the stationary statistics)."""
    level, spread = by_condition(evidence.rows('level')), by_condition(evidence.rows('spread'))
    num = den = 0.0
    for r in evidence.rows('correlation'):
        for g in groups:
            if set(r.key.sensors) <= set(g):
                (ra, sa), (rb, sb) = (spread[r.key.condition][x] for x in r.key.sensors)
                num += r.real * ra * rb - r.sim * sa * sb
                den += float(np.mean([level[r.key.condition][x][1] for x in g])) ** 2
    return float(np.sqrt(max(num, 0.0) / den)) if den > 0 and num > 0 else 0.01


def _loop_strength(evidence: Evidence, groups: Sequence[tuple[int, ...]]) -> float | None:
    """The same from the closed loop's spreads: excess variance over squared level."""
    num = den = 0.0
    for g in groups:
        cells = evidence.spread_cells(g, closed_loop=True)
        level = np.array([v for v, _ in cells])
        num += max(float(np.sum([e for _, e in cells])), 0.0)
        den += float(np.sum(level * level))
    return float(np.sqrt(num / den)) if num > 0 and den > 0 else None
