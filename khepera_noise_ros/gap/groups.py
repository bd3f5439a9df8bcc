"""Dependence groups from data: clustering sensors by how strongly their noise moves together.

The evidence for a pair is a z-score per lighting condition (a correlation
against 0, or a real correlation against the simulated one), combined over
conditions with Stouffer's sum.  Sensors are merged by average linkage while
the mean evidence between two clusters stays above ``threshold``; clusters of
two or more sensors are the groups.  Nothing comes from the configuration.
"""
from __future__ import annotations

import numpy as np

from .statistics import Stats
from .where import Comparison

THRESHOLD = 4.0


def cluster(evidence: np.ndarray, threshold: float = THRESHOLD) -> list[list[int]]:
    """Groups (lists of row indices, two or more each) of a symmetric evidence matrix."""
    clusters = [[i] for i in range(evidence.shape[0])]
    while len(clusters) > 1:
        best, pair = -np.inf, None
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


def excess_evidence(c: Comparison, channels) -> tuple[np.ndarray, np.ndarray]:
    """(z, excess) matrices: combined z of real minus simulated correlation per pair, and the
    mean excess correlation, over the conditions compared."""
    return _combine(((k, r - s, z) for k, r, s, z in zip(c.keys, c.real, c.sim, c.z)
                     if k.family == 'correlation'), channels)


def correlation_evidence(stats: Stats, channels) -> tuple[np.ndarray, np.ndarray]:
    """(z, mean correlation) matrices of correlations against zero, from real data alone."""
    se = np.sqrt(stats.variance)
    rows = ((k, v, v / s if s > 0 else 0.0)
            for k, v, s in zip(stats.keys, stats.estimate, se)
            if k.family == 'correlation' and np.isfinite(v) and np.isfinite(s))
    return _combine(rows, channels)


def _combine(rows, channels) -> tuple[np.ndarray, np.ndarray]:
    channels = list(channels)
    n = len(channels)
    zsum, vsum, count = np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n))
    for key, value, z in rows:
        a, b = (channels.index(s) for s in key.sensors)
        for i, j in ((a, b), (b, a)):
            zsum[i, j] += z
            vsum[i, j] += value
            count[i, j] += 1
    with np.errstate(invalid='ignore', divide='ignore'):
        z = np.where(count > 0, zsum / np.sqrt(count), 0.0)
        mean = np.where(count > 0, vsum / count, 0.0)
    return z, mean
