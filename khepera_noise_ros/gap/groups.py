"""Dependence groups from data: clustering sensors by how strongly their noise moves together.

The evidence for a pair is a z-score per lighting condition (a correlation
against 0, or a real correlation against the simulated one), combined over
conditions with Stouffer's sum.  Sensors are merged by average linkage while
the mean evidence between two clusters stays above ``threshold``; clusters of
two or more sensors are the groups.  Nothing comes from the configuration.
"""
from __future__ import annotations

import numpy as np

from . import closednoise
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


# -- fast and slow parts of the residuals -----------------------------------------------

SLOW_WINDOW = 8      # samples averaged into one value of the slow part


def part_sums(rec, part: str) -> dict:
    """{condition: (cross-product matrix, count)} of the ``part`` of run residuals:
    'fast' = first differences within a run (a slow change cancels); 'slow' = means
    of consecutive windows of ``SLOW_WINDOW`` samples about the run's mean (white
    noise averages down)."""
    from . import replay
    used = list(rec.channels_used)
    out: dict = {}
    for r in replay.runs(rec):
        y = rec.readings[r][:, used].astype(np.float64)
        if part == 'fast':
            d = np.diff(y, axis=0)
        else:
            k = y.shape[0] // SLOW_WINDOW
            d = (y[:k * SLOW_WINDOW] - y.mean(axis=0)).reshape(k, SLOW_WINDOW, -1).mean(axis=1)
        if d.shape[0] < 2:
            continue
        d = d - d.mean(axis=0) if part == 'fast' else d
        acc = out.setdefault(str(rec.condition[r[0]]), [0.0, 0])
        acc[0] = acc[0] + d.T @ d
        acc[1] += d.shape[0]
    return out


def part_evidence(real: list, sim: list, channels, part: str) -> tuple[np.ndarray, np.ndarray]:
    """(z, excess) matrices for the ``part`` ('fast' or 'slow') of the residuals: Fisher z
    of real against simulated correlation per condition, Stouffer-combined."""
    n = len(channels)
    zsum, vsum, count = np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n))
    pooled = [_pool([part_sums(r, part) for r in recs]) for recs in (real, sim)]
    for cond, (sr, nr) in pooled[0].items():
        if cond not in pooled[1] or nr < 8:
            continue
        ss, ns = pooled[1][cond]
        cr, cs = _corr(sr), _corr(ss)
        se = np.sqrt(1.0 / max(nr - 3, 1) + 1.0 / max(ns - 3, 1))
        with np.errstate(invalid='ignore'):
            z = (np.arctanh(np.clip(cr, -0.999, 0.999)) -
                 np.arctanh(np.clip(cs, -0.999, 0.999))) / se
        ok = np.isfinite(z)
        zsum += np.where(ok, z, 0.0)
        vsum += np.where(ok, cr - cs, 0.0)
        count += ok
    with np.errstate(invalid='ignore', divide='ignore'):
        z = np.where(count > 0, zsum / np.sqrt(count), 0.0)
        mean = np.where(count > 0, vsum / count, 0.0)
    np.fill_diagonal(z, 0.0)
    return z, mean


def _pool(parts: list) -> dict:
    out: dict = {}
    for p in parts:
        for cond, (s, n) in p.items():
            acc = out.setdefault(cond, [0.0, 0])
            acc[0] = acc[0] + s
            acc[1] += n
    return out


def _corr(s: np.ndarray) -> np.ndarray:
    d = np.sqrt(np.clip(np.diag(s), 1e-12, None))
    return s / d[:, None] / d[None, :]


def fast_evidence(target, c: Comparison, part: str = 'fast') -> np.ndarray:
    """Excess correlation of the fast (or slow) part of the residuals, real against
    simulated, from a fitting target's stationary recordings; the comparison's own
    correlations (the whole residual) when there are none."""
    channels = list(target.recordings[0].channels_used)
    real = target.of_kind('stationary')
    if not real:      # closed loop only: its noise statistics (``gap.closednoise``)
        z = excess_evidence(c, channels)[0]
        return closednoise.evidence(c, channels) if part == 'fast' and not z.any() else z
    sim = target.simulate(kinds=('stationary',))
    return part_evidence(real, sim, channels, part)[0]
