"""The honest remainder: what the named effects leave, and an empirical model of it.

After the compound diagnosis, the held-out comparison with every chosen effect
says which statistics, sensors and conditions are still off, and by how much.
Whatever named effects there are, an ``empirical_noise`` effect is fitted to the
fitting part as measured (nothing is assumed about its shape):

* fast part (first differences of the run residuals, / sqrt 2): per sensor the
  extra variance over the simulator's at each light level, binned at level
  quantiles, as an sd curve; across sensors, the extra covariance as a
  correlation, made positive semi-definite and factored (Cholesky);
* slow part (means of consecutive windows of the residuals): per sensor the
  extra variance as a fraction of the squared level, its correlation time from
  the windows' lag-one autocorrelation, and its correlation across sensors.

It is scored on the held-out part like a named effect, so a user always gets
a simulator that is closer, and knows which part of it has a named cause.
"""
from __future__ import annotations

import math

import numpy as np

from . import effects as fx
from . import replay
from .groups import SLOW_WINDOW
from .target import Target
from .where import ALPHA, Comparison, entries, localise

KNOTS = 5


def describe(c: Comparison, d_before: float, alpha: float = ALPHA, limit: int = 10) -> dict:
    """What is still off in the held-out comparison ``c``."""
    sig = c.significant(alpha)
    return {'significant': bool(sig.any()), 'statistics_off': int(sig.sum()),
            'discrepancy': c.discrepancy,
            'share_of_gap_left': c.discrepancy / d_before if d_before > 0 else 0.0,
            'where': [e for e in entries(c, limit, alpha) if e['significant']],
            'localisation': localise(c, alpha)}


def _runs(recs) -> list:
    out = []
    for rec in recs:
        used = list(rec.channels_used)
        for r in replay.runs(rec):
            if r.size >= 2 * SLOW_WINDOW:
                out.append(rec.readings[r][:, used].astype(np.float64))
    return out


def _moments(runs: list, edges: np.ndarray, channels: int) -> dict:
    """Fast variance per (level bin, sensor), fast covariance, slow moments."""
    k = len(edges) - 1
    var = np.zeros((k, channels))
    cnt = np.zeros((k, channels))
    cov = np.zeros((channels, channels))
    n_fast = 0
    slow = np.zeros((channels, channels))
    lag = np.zeros(channels)
    n_slow, n_lag = 0, 0
    level2 = np.zeros(channels)
    for y in runs:
        mean = y.mean(axis=0)
        d = np.diff(y, axis=0) / math.sqrt(2.0)
        b = np.clip(np.searchsorted(edges, mean, side='right') - 1, 0, k - 1)
        for s in range(channels):
            var[b[s], s] += (d[:, s] ** 2).sum()
            cnt[b[s], s] += d.shape[0]
        cov += d.T @ d
        n_fast += d.shape[0]
        m = y.shape[0] // SLOW_WINDOW
        w = (y[:m * SLOW_WINDOW] - mean).reshape(m, SLOW_WINDOW, -1).mean(axis=1)
        slow += w.T @ w
        n_slow += m
        lag += (w[1:] * w[:-1]).sum(axis=0)
        n_lag += m - 1
        level2 += mean ** 2 * m
    with np.errstate(invalid='ignore', divide='ignore'):
        return {'var': var / cnt, 'cov': cov / max(n_fast, 1), 'slow': slow / max(n_slow, 1),
                'lag': lag / max(n_lag, 1), 'level2': level2 / max(n_slow, 1)}


def _factor(cov: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor of the correlation of a covariance, clipped to PSD."""
    sd = np.sqrt(np.clip(np.diag(cov), 1e-12, None))
    corr = cov / sd[:, None] / sd[None, :]
    w, v = np.linalg.eigh((corr + corr.T) / 2)
    corr = (v * np.clip(w, 1e-6, None)) @ v.T
    d = np.sqrt(np.diag(corr))
    corr = corr / d[:, None] / d[None, :]
    return np.linalg.cholesky(corr)


def fit(target: Target) -> fx.EmpiricalNoise | None:
    """The empirical remainder of ``target`` (its ``given`` effects in the simulator)."""
    real_recs = target.of_kind('stationary')
    if not real_recs:
        return None
    sim_recs = target.simulate(kinds=('stationary',))
    real, sim = _runs(real_recs), _runs(sim_recs)
    if not real or not sim:
        return None
    sensors = tuple(int(s) for s in real_recs[0].channels_used)
    n = len(sensors)
    levels = np.concatenate([y.mean(axis=0) for y in real])
    edges = np.unique(np.quantile(levels, np.linspace(0, 1, KNOTS + 1)))
    if edges.size < 2:
        edges = np.array([levels.min(), levels.min() + 1.0])
    edges[-1] += 1e-9
    mr, ms = _moments(real, edges, n), _moments(sim, edges, n)
    extra = np.nan_to_num(mr['var'] - ms['var'], nan=0.0)
    spread = np.sqrt(np.clip(extra, 0.0, None)).T               # (sensors, knots)
    centres = [(lo + hi) / 2 for lo, hi in zip(edges[:-1], edges[1:])]
    fast_cov = mr['cov'] - ms['cov']
    mixing = _factor(fast_cov) if np.all(np.diag(fast_cov) > 0) else np.eye(n)
    slow_extra = np.clip(np.diag(mr['slow'] - ms['slow']), 0.0, None)
    slow_sd = np.sqrt(slow_extra / np.clip(mr['level2'], 1.0, None))
    with np.errstate(invalid='ignore', divide='ignore'):
        ratio = (mr['lag'] - ms['lag']) / np.where(slow_extra > 0, slow_extra, np.nan)
        rho = np.nanmedian(np.clip(ratio, 0.01, 0.99)) if np.isfinite(ratio).any() \
            else np.nan
    tau = -SLOW_WINDOW / math.log(rho) if np.isfinite(rho) else 30.0
    slow_cov = mr['slow'] - ms['slow']
    slow_mix = _factor(slow_cov) if np.all(np.diag(slow_cov) > 0) else np.eye(n)
    if not (spread.any() or slow_sd.any()):
        return None
    return fx.EmpiricalNoise(
        sensors, tuple(round(float(c), 2) for c in centres),
        tuple(round(float(v), 4) for v in spread.ravel()),
        tuple(round(float(v), 5) for v in mixing.ravel()),
        tuple(round(float(v), 6) for v in slow_sd),
        round(float(np.clip(tau, 1.0, 1e4)), 2),
        tuple(round(float(v), 5) for v in slow_mix.ravel()))
