"""Heading residuals of a tracked closed-loop recording, each sensor at its own delay.

A reading that lags L steps takes the light of the heading L steps back.  Each sensor's
reading is fitted within cells of the heading it is *read at*: for every delay L in
``LAGS`` the cells are (condition, 10-degree bin of h(t-L)), the regressors a quadratic
in that heading and the turns to the neighbouring headings h(t-L-1) and h(t-L+1) (at
L = 0 the design of the undelayed view: turns to h(t-1) and h(t-2)).  Each sensor keeps
the delay whose cells leave it the least variance; the residuals of every sensor are
taken on the same rows, so their covariance and lag-1 products are per-episode sums
like the other closed-loop statistics.  The same rule runs on the real and the
simulated side.  See docs/diagnosis.md ("Heading residuals at each sensor's delay").
"""
from __future__ import annotations

import numpy as np
from scipy import sparse

LAGS = (0, 1, 2, 3)               # delays tried (a sensor latency of up to three steps)
HEADING_BIN = 10.0                # degrees per heading bin
BIN_DENSITY = 0.5                 # samples per episode a heading bin needs to be used
REGRESSORS = 5                    # per cell: level, heading, its square, two turns
CLEAR = 0.9                       # a design is preferred where it leaves a tenth less


def residuals(r, heading, condition, pair, episodes: int):
    """(residuals (N, 8), usable rows (N,), delay per sensor (8,)).

    Residuals are scaled by sqrt(n / (n - REGRESSORS)) of their cell, so their squares
    estimate the noise variance whatever the cell's count; rows without the earlier
    steps a chosen design reaches back to, or in a cell it visits too rarely, are not
    usable (zero residual).  The delays are chosen on the rows every design can use."""
    fits, var = _fits(r, heading, condition, pair, episodes)
    if var is None:
        return np.zeros_like(r), np.zeros(len(r), bool), np.zeros(r.shape[1], np.int64)
    lag = np.where(delayed(var), np.argmin(var, axis=0), 0)
    e = np.stack([fits[lag[k]][0][:, k] for k in range(r.shape[1])], axis=1)
    use = np.logical_and.reduce([fits[j][1] for j in np.unique(lag)])
    return np.where(use[:, None], e, 0.0), use, np.asarray(LAGS)[lag]


def variances(r, heading, condition, pair, episodes: int):
    """(lags, 8) residual variance of each sensor at each delay (None without rows)."""
    return _fits(r, heading, condition, pair, episodes)[1]


def delayed(var: np.ndarray) -> np.ndarray:
    """Per sensor: a delay leaves clearly less (by a tenth) than the undelayed design.  On
    a flat light every delay fits alike; there the undelayed design is the default."""
    return var[1:].min(axis=0) < CLEAR * var[0]


def prompt(var: np.ndarray) -> np.ndarray:
    """Per sensor: the undelayed design leaves clearly less than every delay."""
    return var[0] < CLEAR * var[1:].min(axis=0)


def _fits(r, heading, condition, pair, episodes: int):
    _, cond = np.unique(condition, return_inverse=True)
    h = np.mod(heading + 180.0, 360.0)
    have = [pair.copy()]                         # have[j]: j + 1 earlier steps in the episode
    for j in range(1, max(LAGS) + 1):
        have.append(have[-1] & np.r_[np.zeros(j, bool), pair[:-j]])
    # the design at delay L reaches back to h(t-L-1) (the undelayed one to h(t-2))
    fits = [_fit(r, h, cond, have[max(lag, 1)], lag, episodes) for lag in LAGS]
    common = np.logical_and.reduce([ok for _, ok in fits])
    if not common.any():
        return fits, None
    return fits, np.stack([np.mean(e[common] ** 2, axis=0) for e, _ in fits])


def _fit(r, h, cond, have, lag: int, episodes: int):
    """(scaled residuals, usable rows) of the design at delay ``lag``."""
    at = _shift(h, lag)
    b = np.floor(at / HEADING_BIN).astype(np.int64)
    _, cell = np.unique(cond * 1000 + b, return_inverse=True)
    n = np.bincount(cell, have.astype(np.float64))
    centre = np.bincount(cell, have * at) / np.maximum(n, 1)
    hc = at - centre[cell]
    near = (lag + 1, lag + 2) if lag == 0 else (lag + 1, lag - 1)
    turns = [_wrap(_shift(h, j) - at) for j in near]
    x = np.stack([np.ones_like(h), hc, hc * hc] + turns, axis=1)
    use = have & (n[cell] >= max(BIN_DENSITY * episodes, REGRESSORS + 2))
    cells, n, k = int(cell.max()) + 1, len(h), r.shape[1]
    w = use.astype(np.float64)
    pick = sparse.csr_matrix((w, (cell, np.arange(n))), shape=(cells, n))
    xx = np.asarray(pick @ (x[:, :, None] * x[:, None, :]).reshape(n, -1)).reshape(
        cells, REGRESSORS, REGRESSORS)
    xr = np.asarray(pick @ (x[:, :, None] * r[:, None, :]).reshape(n, -1)).reshape(
        cells, REGRESSORS, k)
    scale = np.trace(xx, axis1=-2, axis2=-1)[..., None, None] + 1e-12
    beta = np.linalg.solve(xx + 1e-10 * scale * np.eye(REGRESSORS), xr)
    e = r - np.einsum('ni,nik->nk', x, beta[cell])
    count = np.bincount(cell, w, minlength=cells)
    with np.errstate(divide='ignore', invalid='ignore'):
        inflate = np.where(count > REGRESSORS, np.sqrt(count / (count - REGRESSORS)), 0.0)
    return np.where(use[:, None], e * inflate[cell][:, None], 0.0), use


def _shift(h: np.ndarray, lag: int) -> np.ndarray:
    """h(t - lag) (rows without that history are not usable)."""
    if lag == 0:
        return h
    out = np.zeros_like(h)
    out[lag:] = h[:-lag]
    return out


def _wrap(d: np.ndarray) -> np.ndarray:
    return np.mod(d + 180.0, 360.0) - 180.0
