"""Closed-loop noise statistics: the structure of the readings' noise while the robot
turns (spread by level, correlation across sensors, lag-1 autocorrelation).

Two views, both as per-episode sums (episodes are the closed-loop blocks):

* *still pairs* (always): first differences of consecutive readings where the
  previous command did not turn the robot and no knock came; the light did not
  move, so the difference is noise alone (headings need not be known).
* *heading residuals* (headings recorded): readings minus a fit in heading and two
  turns within their (condition, heading bin), each sensor at the delay whose heading
  fits it best (``gap.headinglag``).

See docs/diagnosis.md for why and their limits.
"""
from __future__ import annotations

import numpy as np
from scipy import sparse

from . import headinglag, loopchange
from .blocks import Key

BANDS = (0.0, 175.0, 350.0)       # lower edges of the level bands (readings; 525 is dark)
VIEWS = ('still', 'residual')
FAMILIES = frozenset(f'loop_{v}_{s}' for v in VIEWS
                     for s in ('spread', 'correlation', 'autocorrelation')) | loopchange.FAMILIES


def episode_parts(rec, perturb_every: int, change: bool = False) -> dict:
    """{name: (episodes, ...) sums} of both views, episodes in ``np.unique`` order."""
    episodes, ep, order, steps, pair = ordered(rec)
    r = rec.readings[order][:, :8].astype(np.float64)
    power = np.nan_to_num(rec.power[order], nan=1.0)
    still = pair & np.r_[False, power[:-1] == 0] & (steps % perturb_every != 0)
    d = np.zeros_like(r)
    d[1:] = r[1:] - r[:-1]
    level = np.zeros_like(r)
    level[1:] = (r[1:] + r[:-1]) / 2
    # names distinct from ``gap.closedloop``'s own sums: ``still_`` and ``res_``
    parts = _view(d, level, still, still & np.r_[False, still[:-1]], ep, episodes.size,
                  scale=0.5)                   # var(d) = 2 var(noise) for white noise
    heading = rec.heading_deg[order]
    tracked = bool(np.isfinite(heading).all())
    # the change residuals stand in for the heading residuals on a robot nobody tracked;
    # a simulated side always knows its headings: it gives both, the real side chooses.
    # Only with ``change`` (no stationary recording): beside one, the emulated robot's
    # turn error was lost to them (test_gap_compound)
    if change and (not tracked or rec.manifest.get('source') == 'simulator'):
        parts.update(loopchange.episode_parts(rec, perturb_every, order, ep, steps, r, power,
                                              episodes.size, _by))
    if tracked:
        parts.update(_residual_parts(r, heading, rec.condition[order], pair, ep,
                                     episodes.size))
    return parts


def ordered(rec) -> tuple:
    """(episodes, episode index, sample order, steps, pair) of a closed-loop recording in
    episode and step order; ``pair``: the sample and the one before it are consecutive
    steps of one episode."""
    episodes, ep = np.unique(rec.episode, return_inverse=True)
    order = np.lexsort((rec.step, ep))
    ep, steps = ep[order], rec.step[order]
    pair = np.r_[False, (ep[1:] == ep[:-1]) & (steps[1:] == steps[:-1] + 1)]
    return episodes, ep, order, steps, pair


def _residual_parts(r, heading, condition, pair, ep, episodes: int) -> dict:
    """Per-episode sums of the heading-residual view: each sensor's residuals at its own
    delay (``gap.headinglag``), their cross products and lag-1 products."""
    e, use, _ = headinglag.residuals(r, heading, condition, pair, episodes)
    n = len(r)
    lagged = use & pair & np.r_[False, use[:-1]]
    lag = np.zeros_like(e)
    lag[1:] = e[1:] * e[:-1]
    return {'res_n': _by(ep, use[:, None].astype(np.float64), episodes),
            'res_s2': _by(ep, (e[:, :, None] * e[:, None, :]).reshape(n, -1),
                          episodes).reshape(episodes, 8, 8),
            'res_lag_n': _by(ep, lagged[:, None].astype(np.float64), episodes),
            'res_lag_s': _by(ep, lag * lagged[:, None], episodes)}


def _view(x: np.ndarray, level: np.ndarray, use: np.ndarray, lagged: np.ndarray,
          ep: np.ndarray, episodes: int, scale: float) -> dict:
    """Sums per episode: count, cross products, per-band counts and squares (band by each
    sensor's own level), lag-1 products (``lagged`` marks t whose t-1 is used too)."""
    band = np.searchsorted(np.array(BANDS), level, side='right') - 1     # (N, 8)
    onehot = (band[:, None, :] == np.arange(len(BANDS))[None, :, None]) & use[:, None, None]
    xs = x * use[:, None]
    lag = np.zeros_like(x)
    lag[1:] = x[1:] * x[:-1]
    n = len(x)
    return {'still_n': _by(ep, use[:, None].astype(np.float64), episodes),
            'still_s2': scale * _by(ep, (xs[:, :, None] * xs[:, None, :]).reshape(n, -1),
                                    episodes).reshape(episodes, 8, 8),
            'still_band_n': _by(ep, onehot.reshape(n, -1).astype(np.float64),
                                episodes).reshape(episodes, len(BANDS), 8),
            'still_band_s2': scale * _by(ep, (onehot * (xs * xs)[:, None, :]).reshape(n, -1),
                                         episodes).reshape(episodes, len(BANDS), 8),
            'still_lag_n': _by(ep, lagged[:, None].astype(np.float64), episodes),
            'still_lag_s': scale * _by(ep, lag * lagged[:, None], episodes)}


def _by(ep: np.ndarray, values: np.ndarray, episodes: int) -> np.ndarray:
    """(episodes, K) sums of the (N, K) ``values`` by ``ep`` (one sparse product)."""
    pick = sparse.csr_matrix((np.ones(ep.size), (ep, np.arange(ep.size))),
                             shape=(episodes, ep.size))
    return np.asarray(pick @ values, np.float64)


def stats(b, sums: np.ndarray, s: int, condition: str) -> tuple[list, list]:
    """(keys, columns) of stratum ``s`` (one condition) from the (R, S, D) sums."""
    keys, cols = [], []
    views = [('still', _still(b, sums, s))]
    if b.extra['heading']:
        views.append(('residual', _residual(b, sums, s)))
    for view, (n, cov, bands, lag) in views:
        if n[0] < 8:                         # too few samples to say anything
            continue
        sd = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))             # (R, 8)
        for part, count, spread in bands:
            for k in range(8):
                if count[0, k] >= 8:
                    keys.append(Key(f'loop_{view}_spread', (k,), condition, part))
                    cols.append(spread[:, k])
        corr = cov / (sd[:, :, None] * sd[:, None, :])
        for k in range(8):
            for m in range(k + 1, 8):
                keys.append(Key(f'loop_{view}_correlation', (k, m), condition, None))
                cols.append(corr[:, k, m])
        if lag is not None:
            part = 'lag 1 of differences' if view == 'still' else 'lag 1'
            for k in range(8):
                keys.append(Key(f'loop_{view}_autocorrelation', (k,), condition, part))
                cols.append(lag[:, k])
    more_keys, more_cols = loopchange.stats(b, sums, s, condition)
    return keys + more_keys, cols + more_cols


def _still(b, sums, s):
    """(count, covariance, spread bands, lag-1 autocorrelation) of the still view."""
    n = b.part(sums, 'still_n')[:, s, 0]
    cov = b.part(sums, 'still_s2')[:, s] / n[:, None, None]
    band_n = b.part(sums, 'still_band_n')[:, s]
    spread = np.sqrt(b.part(sums, 'still_band_s2')[:, s] / band_n)
    bands = [(f'level {lo:g}-{hi:g}', band_n[:, j], spread[:, j])
             for j, (lo, hi) in enumerate(zip(BANDS, BANDS[1:] + (525.0,)))]
    lag_n = b.part(sums, 'still_lag_n')[:, s, 0]
    lag = None
    if lag_n[0] >= 8:
        lag = b.part(sums, 'still_lag_s')[:, s] / lag_n[:, None] \
            / np.diagonal(cov, axis1=-2, axis2=-1)
    return n, cov, bands, lag


def _residual(b, sums, s):
    """The heading-residual view: each sensor's residuals at its own delay, scaled for
    their cells' degrees of freedom (``gap.headinglag``).  One spread per sensor: where
    the light is steep a band's residuals are not noise alone."""
    n = b.part(sums, 'res_n')[:, s, 0]
    cov = b.part(sums, 'res_s2')[:, s] / n[:, None, None]
    bands = [('level 0-525', np.repeat(n[:, None], 8, axis=1),
              np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1)))]
    lag_n = b.part(sums, 'res_lag_n')[:, s, 0]
    lag = None
    if lag_n[0] >= 8:
        lag = b.part(sums, 'res_lag_s')[:, s] / lag_n[:, None] \
            / np.diagonal(cov, axis1=-2, axis2=-1)
    return n, cov, bands, lag


CORRELATIONS = ('loop_still_correlation', 'loop_residual_correlation', 'loop_change_correlation')
SPREADS = ('loop_still_spread', 'loop_residual_spread', 'loop_change_spread')


def evidence(c, channels) -> np.ndarray:
    """Combined z (Stouffer over conditions and views) that a pair's closed-loop noise is
    more correlated than simulated: the fast part where the still view has it."""
    channels = list(channels)
    n = len(channels)
    zsum, count = np.zeros((n, n)), np.zeros((n, n))
    # the change residuals only where no direct view of the noise exists (as spread_cells)
    direct = {k.family for k in c.keys} & set(CORRELATIONS[:2])
    families = direct or set(CORRELATIONS)
    for k, z in zip(c.keys, c.z):
        if k.family in families \
                and np.isfinite(z) and all(s in channels for s in k.sensors):
            a, b = (channels.index(s) for s in k.sensors)
            for i, j in ((a, b), (b, a)):
                zsum[i, j] += z
                count[i, j] += 1
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(count > 0, zsum / np.sqrt(count), 0.0)


def spread_rows(c) -> list:
    """(key, real, sim, se, z) of the closed-loop spreads (both views)."""
    return [(k, r, s, se, z) for k, r, s, se, z in zip(c.keys, c.real, c.sim, c.se, c.z)
            if k.family in SPREADS]


def spread_cells(c, sensors, real) -> list:
    """[(level, excess variance)] of ``sensors`` for a spread law: the still view per
    level band (at the band's middle), the residual view per sensor at its mean level
    (``closed_loop_level`` of the ``real`` statistics): sensors at different levels
    trace the law together."""
    level = {(k.sensors, k.condition): v for k, v in zip(real.keys, real.estimate)
             if k.family == 'closed_loop_level'}
    out = []
    rows = spread_rows(c)
    # the change residuals' regression takes part of the noise too: a fallback only
    direct = [row for row in rows if row[0].family != 'loop_change_spread']
    for k, r, s, se, z in direct or rows:
        if k.sensors[0] not in sensors or not (np.isfinite(r) and np.isfinite(s)):
            continue
        excess = r * r - s * s
        if k.family != 'loop_residual_spread':     # by level band
            lo, hi = (float(v) for v in k.part.split()[1].split('-'))
            out.append(((lo + hi) / 2, excess))
        elif (k.sensors, k.condition) in level:
            out.append((level[(k.sensors, k.condition)], excess))
    return out


def shared_strength(c, groups, real) -> float | None:
    """Moment estimate of shared noise sd as a fraction of the group's mean level, from
    the closed-loop spreads (``spread_cells``): excess variance over squared level, for a
    recording with no stationary statistics; None without usable cells."""
    num = den = 0.0
    for g in groups:
        cells = spread_cells(c, set(g), real)
        if cells:
            level = np.array([v for v, _ in cells])
            num += max(float(np.sum([e for _, e in cells])), 0.0)
            den += float(np.sum(level * level))
    return float(np.sqrt(num / den)) if num > 0 and den > 0 else None
