"""``empirical_noise``: the remainder no named effect explains, as measured.

Not in the vocabulary: the diagnosis fits it to whatever the chosen effects leave,
assuming nothing of its shape, and scores it on held-out data like a named effect.  Fast
part (first differences of the run residuals / sqrt 2): per sensor the extra sd at each
light level (bins at level quantiles); across sensors the extra correlation (made positive
semi-definite).  Slow part (means of windows of the residuals): per sensor the extra
variance over the squared level, its correlation time (the windows' lag-one
autocorrelation) and its correlation.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .base import Array, Candidate, Effect, Evidence, Stage, Step, ar1, param, replaced, rows

KNOTS = 5
WINDOW = 8        # samples averaged into one value of the slow part


@dataclass(frozen=True)
class EmpiricalNoise(Effect, name='empirical_noise', stage=Stage.LIGHT, free=99,
                     summary='the remainder no named effect explains, as measured'):
    """Fast: per sensor an extra sd interpolated over ``levels`` from ``spread`` (a row of
    knots per sensor), mixed across sensors by the lower triangular ``mixing``.  Slow: an
    AR(1) of ``slow_time_constant`` samples moving each gain by ``slow_sd``, mixed by
    ``slow_mixing``."""

    sensors: tuple[int, ...] = param((), 'sensors of the model', 'sensors')
    levels: tuple[float, ...] = param((0.0, 525.0), 'light levels of the knots', 'floats',
                                      ascending=True)
    spread: tuple[float, ...] = param((), 'extra sd at each knot, sensor by sensor', 'floats')
    mixing: tuple[float, ...] = param((), 'fast mixing matrix, row by row', 'floats')
    slow_sd: tuple[float, ...] = param((), 'slow sd per sensor (a fraction)', 'floats')
    slow_time_constant: float = param(30.0, 'correlation time of the slow part, samples',
                                      above=0.0)
    slow_mixing: tuple[float, ...] = param((), 'slow mixing matrix, row by row', 'floats')

    def inconsistency(self) -> str:
        n = len(self.sensors)
        ok = len(self.levels) >= 1 and len(self.spread) == n * len(self.levels) and \
            len(self.mixing) in (0, n * n) and len(self.slow_sd) in (0, n) and \
            len(self.slow_mixing) in (0, n * n)
        return '' if ok else ('needs one spread per sensor and level, n x n mixings and one '
                              'slow_sd per sensor')

    def _arrays(self, channels: int) -> tuple[list[int], Array, Array, Array, Array, float]:
        """The rows, the fast sd at the knots and mixing, the slow sd and mixing, and the
        slow part's AR(1) coefficient."""
        located, n = rows(self.sensors, channels), len(self.sensors)
        spread = np.asarray(self.spread, float).reshape(n, len(self.levels))
        mix = np.asarray(self.mixing, float).reshape(n, n) if self.mixing else np.eye(n)
        slow = np.asarray(self.slow_sd, float) if self.slow_sd else np.zeros(n)
        smix = np.asarray(self.slow_mixing, float).reshape(n, n) if self.slow_mixing else np.eye(n)
        return located, spread, mix, slow, smix, math.exp(-1.0 / self.slow_time_constant)

    def _fast(self, level: Array, z: Array, spread: Array, mix: Array) -> Array:
        """Fast noise of (sensors, ...) levels from (sensors, ...) normal draws."""
        sd = np.stack([np.interp(level[k], self.levels, spread[k]) for k in range(len(spread))])
        out: Array = sd * np.einsum('ij,j...->i...', mix, z)
        return out

    def start(self, robots: int, channels: int, rng: np.random.Generator) -> Step:
        located, spread, mix, slow, smix, a = self._arrays(channels)
        state = smix @ rng.standard_normal((len(located), robots))

        def step(level: Array) -> Array:
            nonlocal state
            fast = self._fast(level[located], rng.standard_normal((len(located), robots)),
                              spread, mix)
            out = replaced(level, located, level[located] * (1.0 + slow[:, None] * state) + fast)
            state = a * state + math.sqrt(1 - a * a) * (smix @ rng.standard_normal(state.shape))
            return out
        return step

    def over_time(self, level: Array, rng: np.random.Generator) -> Array:
        located, spread, mix, slow, smix, a = self._arrays(level.shape[1])
        t, n, r = level.shape[0], len(located), level.shape[2]
        d = rng.standard_normal((2 * t + 1, n, r))       # as ``start`` draws: slow, fast, ...
        z = np.einsum('ij,tjr->tir', smix, d[0:2 * t:2])
        z[1:] *= math.sqrt(1 - a * a)
        fast = self._fast(level[:, located].transpose(1, 0, 2), d[1::2].transpose(1, 0, 2),
                          spread, mix).transpose(1, 0, 2)
        return replaced(level, located,
                        level[:, located] * (1.0 + slow[None, :, None] * ar1(z, a)) + fast)

    @classmethod
    def fit(cls, evidence: Evidence) -> Candidate:
        real, sim = ([y for y in evidence.stationary_runs(simulated) if y.shape[0] >= 2 * WINDOW]
                     for simulated in (False, True))
        if not real or not sim:
            return cls.nothing('no stationary runs to measure')
        sensors = tuple(int(s) for s in evidence.channels)
        n = len(sensors)
        levels = np.concatenate([y.mean(axis=0) for y in real])
        edges = np.unique(np.quantile(levels, np.linspace(0, 1, KNOTS + 1)))
        if edges.size < 2:
            edges = np.array([levels.min(), levels.min() + 1.0])
        edges[-1] += 1e-9
        mr, ms = _moments(real, edges, n), _moments(sim, edges, n)
        spread = np.sqrt(np.clip(np.nan_to_num(mr['var'] - ms['var'], nan=0.0), 0.0, None)).T
        centres = [(lo + hi) / 2 for lo, hi in zip(edges[:-1], edges[1:])]
        mixing = _factor(mr['cov'] - ms['cov'])
        slow_extra = np.clip(np.diag(mr['slow'] - ms['slow']), 0.0, None)
        slow_sd = np.sqrt(slow_extra / np.clip(mr['level2'], 1.0, None))
        with np.errstate(invalid='ignore', divide='ignore'):
            ratio = (mr['lag'] - ms['lag']) / np.where(slow_extra > 0, slow_extra, np.nan)
            rho = np.nanmedian(np.clip(ratio, 0.01, 0.99)) if np.isfinite(ratio).any() else np.nan
        tau = -WINDOW / math.log(rho) if np.isfinite(rho) else 30.0
        slow_mix = _factor(mr['slow'] - ms['slow'])
        if not (spread.any() or slow_sd.any()):
            return cls.nothing('nothing left to measure')

        def rounded(values: Any, digits: int) -> tuple[float, ...]:
            return tuple(round(float(v), digits) for v in np.ravel(values))
        effect = cls(sensors, rounded(centres, 2), rounded(spread, 4), rounded(mixing, 5),
                     rounded(slow_sd, 6), round(float(np.clip(tau, 1.0, 1e4)), 2),
                     rounded(slow_mix, 5))
        return Candidate(cls.name, effect, 'the remainder as measured')


def _moments(runs: list[Array], edges: Array, channels: int) -> dict[str, Array]:
    """Fast variance per (level bin, sensor), fast covariance, slow moments."""
    k = len(edges) - 1
    var, cnt = np.zeros((k, channels)), np.zeros((k, channels))
    cov, slow = np.zeros((channels, channels)), np.zeros((channels, channels))
    lag, level2 = np.zeros(channels), np.zeros(channels)
    n_fast = n_slow = n_lag = 0
    for y in runs:
        mean = y.mean(axis=0)
        d = np.diff(y, axis=0) / math.sqrt(2.0)
        b = np.clip(np.searchsorted(edges, mean, side='right') - 1, 0, k - 1)
        var[b, np.arange(channels)] += (np.ascontiguousarray(d.T) ** 2).sum(axis=1)
        cnt[b, np.arange(channels)] += d.shape[0]
        cov += d.T @ d
        n_fast += d.shape[0]
        m = y.shape[0] // WINDOW
        w = (y[:m * WINDOW] - mean).reshape(m, WINDOW, -1).mean(axis=1)
        slow += w.T @ w
        n_slow += m
        lag += (w[1:] * w[:-1]).sum(axis=0)
        n_lag += m - 1
        level2 += mean ** 2 * m
    with np.errstate(invalid='ignore', divide='ignore'):
        return {'var': var / cnt, 'cov': cov / max(n_fast, 1), 'slow': slow / max(n_slow, 1),
                'lag': lag / max(n_lag, 1), 'level2': level2 / max(n_slow, 1)}


def _factor(cov: Array) -> Array:
    """Lower Cholesky factor of the correlation of a covariance, clipped to PSD (the
    identity unless every variance is positive)."""
    if not np.all(np.diag(cov) > 0):
        return np.eye(len(cov))
    sd = np.sqrt(np.clip(np.diag(cov), 1e-12, None))
    corr = cov / sd[:, None] / sd[None, :]
    w, v = np.linalg.eigh((corr + corr.T) / 2)
    corr = (v * np.clip(w, 1e-6, None)) @ v.T
    d = np.sqrt(np.diag(corr))
    return np.linalg.cholesky(corr / d[:, None] / d[None, :])
