"""Closed-loop noise statistics: the structure of the readings' noise while the robot
turns (spread by level, correlation across sensors, lag-1 autocorrelation).

Two views, both as per-episode sums (episodes are the closed-loop blocks):

* *still pairs* (always): first differences of consecutive readings where the
  previous command did not turn the robot and no knock came; the light did not
  move, so the difference is noise alone (headings need not be known).
* *heading residuals* (headings recorded): readings minus a line in heading fitted
  to their (condition, heading bin), every sample.

See docs/diagnosis.md for why and their limits.
"""
from __future__ import annotations

import numpy as np

from .blocks import Key

BANDS = (0.0, 175.0, 350.0)       # lower edges of the level bands (readings; 525 is dark)
HEADING_BIN = 10.0                # degrees per heading bin of the residual view
BIN_DENSITY = 0.25                # samples per episode a heading bin needs to be used
VIEWS = ('still', 'residual')
FAMILIES = frozenset(f'loop_{v}_{s}' for v in VIEWS
                     for s in ('spread', 'correlation', 'autocorrelation'))


def episode_parts(rec, perturb_every: int) -> dict:
    """{name: (episodes, ...) sums} of both views, episodes in ``np.unique`` order."""
    episodes, ep = np.unique(rec.episode, return_inverse=True)
    order = np.lexsort((rec.step, ep))
    ep, steps = ep[order], rec.step[order]
    r = rec.readings[order][:, :8].astype(np.float64)
    power = np.nan_to_num(rec.power[order], nan=1.0)
    # a pair (t-1, t): same episode, consecutive steps
    pair = np.r_[False, (ep[1:] == ep[:-1]) & (steps[1:] == steps[:-1] + 1)]
    still = pair & np.r_[False, power[:-1] == 0] & (steps % perturb_every != 0)
    d = np.zeros_like(r)
    d[1:] = r[1:] - r[:-1]
    level = np.zeros_like(r)
    level[1:] = (r[1:] + r[:-1]) / 2
    parts = _view(d, level, still, still & np.r_[False, still[:-1]], ep, episodes.size,
                  scale=0.5)                   # var(d) = 2 var(noise) for white noise
    heading = rec.heading_deg[order]
    known = bool(np.isfinite(heading).all())
    e = _residuals(r, heading, rec.condition[order], episodes.size) if known \
        else np.zeros_like(r)
    ok = np.isfinite(e).all(axis=1) & known
    e = np.nan_to_num(e)
    parts.update({f'res_{k}': v for k, v in
                  _view(e, r, ok, pair & ok & np.r_[False, ok[:-1]], ep, episodes.size,
                        scale=1.0).items()})
    return parts


def _residuals(r: np.ndarray, heading: np.ndarray, condition: np.ndarray,
               episodes: int) -> np.ndarray:
    """Readings minus a line in heading fitted to their (condition, heading bin): the
    light's gradient within a bin is removed, not only its mean.  Scaled by
    sqrt(n / (n - 2)) so that their variance is unbiased whatever the bin's count (real
    and simulated data have different counts).  NaN in bins visited rarely (under
    ``BIN_DENSITY`` samples per episode, a rate that does not depend on how many copies
    are simulated): there a line through a few points leaves the light's curvature."""
    _, cond = np.unique(condition, return_inverse=True)
    b = np.floor(np.mod(heading + 180.0, 360.0) / HEADING_BIN).astype(np.int64)
    _, cell = np.unique(cond * 1000 + b, return_inverse=True)
    n = np.bincount(cell).astype(np.float64)
    h = np.mod(heading + 180.0, 360.0)
    hc = h - (np.bincount(cell, h) / n)[cell]
    shh = np.bincount(cell, hc * hc)
    out = np.empty_like(r)
    for k in range(r.shape[1]):
        mean = np.bincount(cell, r[:, k]) / n
        with np.errstate(divide='ignore', invalid='ignore'):
            slope = np.where(shh > 1e-9, np.bincount(cell, hc * r[:, k]) / shh, 0.0)
        out[:, k] = r[:, k] - mean[cell] - slope[cell] * hc
    with np.errstate(divide='ignore', invalid='ignore'):
        factor = np.where((n > 2) & (n >= BIN_DENSITY * episodes), np.sqrt(n / (n - 2)),
                          np.nan)
    return out * factor[cell][:, None]


def _view(x: np.ndarray, level: np.ndarray, use: np.ndarray, lagged: np.ndarray,
          ep: np.ndarray, episodes: int, scale: float) -> dict:
    """Sums per episode: count, cross products, per-band counts and squares (band by each
    sensor's own level), lag-1 products (``lagged`` marks t whose t-1 is used too)."""
    band = np.searchsorted(np.array(BANDS), level, side='right') - 1     # (N, 8)
    onehot = (band[:, None, :] == np.arange(len(BANDS))[None, :, None]) & use[:, None, None]
    xs = x * use[:, None]
    lag = np.zeros_like(x)
    lag[1:] = x[1:] * x[:-1]
    out = {'n': _by(ep, use[:, None].astype(np.float64), episodes),
           's2': _by(ep, (xs[:, :, None] * xs[:, None, :]).reshape(len(x), -1),
                     episodes).reshape(episodes, 8, 8) * scale,
           'band_n': _by(ep, onehot.reshape(len(x), -1).astype(np.float64),
                         episodes).reshape(episodes, len(BANDS), 8),
           'band_s2': _by(ep, (onehot * (xs * xs)[:, None, :]).reshape(len(x), -1),
                          episodes).reshape(episodes, len(BANDS), 8) * scale,
           'lag_n': _by(ep, lagged[:, None].astype(np.float64), episodes),
           'lag_s': _by(ep, lag * lagged[:, None], episodes) * scale}
    return out


def _by(ep: np.ndarray, values: np.ndarray, episodes: int) -> np.ndarray:
    out = np.zeros((episodes, values.shape[1]))
    np.add.at(out, ep, values)
    return out


def stats(b, sums: np.ndarray, s: int, condition: str) -> tuple[list, list]:
    """(keys, columns) of stratum ``s`` (one condition) from the (R, S, D) sums."""
    keys, cols = [], []
    for view, prefix in (('still', ''), ('residual', 'res_')):
        if view == 'residual' and not b.extra['heading']:
            continue
        n = b.part(sums, prefix + 'n')[:, s, 0]
        if not np.any(n[:1] >= 8):                   # too few samples to say anything
            continue
        s2 = b.part(sums, prefix + 's2')[:, s]           # (R, 8, 8)
        var = np.diagonal(s2, axis1=-2, axis2=-1)        # (R, 8)
        sd = np.sqrt(var)
        band_n = b.part(sums, prefix + 'band_n')[:, s]
        band = np.sqrt(b.part(sums, prefix + 'band_s2')[:, s] / band_n)
        if view == 'residual':      # one band: where the light is steep, the residual
            band_n = band_n.sum(axis=1, keepdims=True)          # spread is not noise alone
            band = np.sqrt(var / n[:, None])[:, None, :]
        for j, lo in enumerate(BANDS[:band.shape[1]]):
            hi = BANDS[j + 1] if j + 1 < band.shape[1] else 525.0
            for k in range(8):
                if band_n[0, j, k] >= 8:
                    keys.append(Key(f'loop_{view}_spread', (k,), condition,
                                    f'level {lo:g}-{hi:g}'))
                    cols.append(band[:, j, k])
        corr = s2 / (sd[:, :, None] * sd[:, None, :])
        for k in range(8):
            for m in range(k + 1, 8):
                keys.append(Key(f'loop_{view}_correlation', (k, m), condition, None))
                cols.append(corr[:, k, m])
        lag_n = b.part(sums, prefix + 'lag_n')[:, s, 0]
        if lag_n[0] >= 8:
            acf = b.part(sums, prefix + 'lag_s')[:, s] / lag_n[:, None] / (var / n[:, None])
            part = 'lag 1 of differences' if view == 'still' else 'lag 1'
            for k in range(8):
                keys.append(Key(f'loop_{view}_autocorrelation', (k,), condition, part))
                cols.append(acf[:, k])
    return keys, cols


def evidence(c, channels) -> np.ndarray:
    """Combined z (Stouffer over conditions and views) that a pair's closed-loop noise is
    more correlated than simulated: the fast part where the still view has it."""
    channels = list(channels)
    n = len(channels)
    zsum, count = np.zeros((n, n)), np.zeros((n, n))
    for k, z in zip(c.keys, c.z):
        if k.family in ('loop_still_correlation', 'loop_residual_correlation') \
                and np.isfinite(z) and all(s in channels for s in k.sensors):
            a, b = (channels.index(s) for s in k.sensors)
            for i, j in ((a, b), (b, a)):
                zsum[i, j] += z
                count[i, j] += 1
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(count > 0, zsum / np.sqrt(count), 0.0)
