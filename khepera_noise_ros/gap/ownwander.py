"""Each sensor's own slow wander, seen beside noise the sensors share.

A drift of each sensor's gain (its own AR(1) wander) adds autocorrelation to that
sensor's residuals, but a fast noise shared by all sensors (a room's flicker) can
be far larger and white, so the residuals' autocorrelation hardly moves.  Within
each run the part a sensor shares with the others (its regression on the mean
residual of the other sensors) is taken out first; what is left is the sensor's
own noise, where a wander of its own keeps its full share.  Real against
simulated, per sensor: the mean autocorrelation of that own part over ``LAGS``,
its standard error from the spread over runs, one-sided z (a wander only adds
autocorrelation), Holm over sensors.
"""
from __future__ import annotations

import numpy as np
from scipy import stats as sps

from . import replay
from .where import ALPHA, holm

LAGS = (1, 3, 10)
SKIP = 3               # first samples of a run left out: the step after a heading change
MIN_RUN = 24           # shorter runs give no usable autocorrelation at the longest lag
MIN_LEVEL = 20.0       # readings; darker cells carry no usable own part (rounding)


def _own(rec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Arrays over runs: (runs, lags, sensors) autocorrelation of each sensor's own part
    at ``LAGS``, (runs, sensors) its lag-1 autocovariance relative to the level, and
    (runs, sensors) a usable mask."""
    used = list(rec.channels_used)
    acf, cov, ok = [], [], []
    for r in replay.runs(rec):
        if r.size < MIN_RUN + SKIP or len(used) < 3:
            continue
        y = rec.readings[r[SKIP:]][:, used].astype(np.float64)
        level = y.mean(axis=0)
        y = y - level
        total = y.sum(axis=1, keepdims=True)
        others = (total - y) / (len(used) - 1)          # mean of the other sensors
        with np.errstate(invalid='ignore', divide='ignore'):
            beta = (y * others).sum(axis=0) / (others * others).sum(axis=0)
        e = y - np.nan_to_num(beta) * others
        den = (e * e).sum(axis=0)
        good = (den > 0) & (level > MIN_LEVEL)
        with np.errstate(invalid='ignore', divide='ignore'):
            a = np.array([(e[:-k] * e[k:]).sum(axis=0) / den for k in LAGS])
            c = (e[:-1] * e[1:]).sum(axis=0) / (e.shape[0] - 1) / np.square(level)
        acf.append(np.where(good, a, np.nan))
        cov.append(np.where(good, c, np.nan))
        ok.append(good)
    n = len(used)
    if not acf:
        return np.empty((0, len(LAGS), n)), np.empty((0, n)), np.empty((0, n), bool)
    return np.array(acf), np.array(cov), np.array(ok)


def _pooled(recs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    parts = [_own(rec) for rec in recs]
    return tuple(np.concatenate([p[i] for p in parts]) for i in range(3))


def excess(real: list, sim: list) -> dict:
    """{sensor: {'z', 'p' (of the mean over ``LAGS``), 'acf' {lag: real - simulated},
    'sd' (the wander's sd as a fraction of the level, from the excess lag-1
    autocovariance)}} of every sensor in the stationary recordings ``real`` against
    their replays ``sim``."""
    if not real or not sim:
        return {}
    used = list(real[0].channels_used)
    (ar, cr, okr), (as_, cs, oks) = _pooled(real), _pooled(sim)
    out = {}
    for k, s in enumerate(used):
        x, y = ar[okr[:, k], :, k].mean(axis=1), as_[oks[:, k], :, k].mean(axis=1)
        if x.size < 3 or y.size < 3:
            continue
        se = np.sqrt(x.var(ddof=1) / x.size + y.var(ddof=1) / y.size)
        if not se > 0:
            continue
        z = float((x.mean() - y.mean()) / se)
        extra = np.nanmean(cr[okr[:, k], k]) - np.nanmean(cs[oks[:, k], k])
        lags = ar[okr[:, k], :, k].mean(axis=0) - as_[oks[:, k], :, k].mean(axis=0)
        out[s] = {'z': z, 'p': float(sps.norm.sf(z)),
                  'acf': {lag: float(v) for lag, v in zip(LAGS, lags)},
                  'sd': float(np.sqrt(max(extra, 0.0)))}
    return out


def wandering(real: list, sim: list) -> dict:
    """The sensors of ``excess`` whose own part is more autocorrelated than simulated
    (one-sided, Holm over sensors at ``ALPHA``)."""
    ex = excess(real, sim)
    sensors = sorted(ex)
    if not sensors:
        return {}
    adjusted = holm(np.array([ex[s]['p'] for s in sensors]))
    return {s: ex[s] for s, q in zip(sensors, adjusted) if q < ALPHA}


def of_target(target) -> dict:
    """``wandering`` of a fitting target's stationary recordings against its simulator
    (with the effects it is given)."""
    real = [r for r, k in zip(target.recordings, target.kinds) if k == 'stationary']
    if not real:
        return {}
    return wandering(real, target.simulate(kinds=('stationary',)))
