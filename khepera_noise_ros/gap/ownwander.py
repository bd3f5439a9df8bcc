"""Each sensor's own slow wander, seen beside noise the sensors share.

A drift of each sensor's gain (its own AR(1) wander) adds autocorrelation to that
sensor's residuals, but a fast noise shared by all sensors (a room's flicker) can
be far larger and white, so the residuals' autocorrelation hardly moves.  Within
each run the part a sensor shares with the others (its regression on the mean
residual of the other sensors) is taken out first; what is left is the sensor's
own noise, where a wander of its own keeps its full share.  Real against
simulated, per sensor: the mean autocorrelation of that own part over ``LAGS``,
its standard error from the spread over runs, one-sided z (a wander only adds
autocorrelation), Holm over sensors; wandering sensors are found one at a time and
left out of the shared part (``wandering``).
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
OWN_CACHE = 64


_OWN: dict = {}


def _own(rec, shared_by=None, memo=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``_own_parts``, remembered per recording and ``shared_by`` (read-only): the sensors
    are taken out one at a time (``wandering``), and every fit of a drift asks again of
    the same real recordings and often of the same remembered replay.  Read-only readings
    (a replay's) are remembered here; others only in ``memo``, a dict of whoever keeps
    them unchanged (a ``Target``)."""
    cols = (rec.readings, rec.episode, rec.step, rec.heading_deg, rec.condition)
    cache = _OWN if not rec.readings.flags.writeable else memo
    if cache is None:
        return _own_parts(rec, shared_by)
    key = tuple(id(c) for c in cols) + (tuple(rec.channels_used),
                                        None if shared_by is None else tuple(shared_by))
    hit = cache.get(key)
    if hit is not None and all(a is b for a, b in zip(hit[0], cols)):
        return hit[1]
    out = _own_parts(rec, shared_by)
    for a in out:
        a.flags.writeable = False
    cache[key] = (cols, out)          # the columns held: their identities stay unique
    if len(cache) > OWN_CACHE:
        cache.pop(next(iter(cache)))
    return out


def _own_parts(rec, shared_by=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Arrays over runs: (runs, lags, sensors) autocorrelation of each sensor's own part
    at ``LAGS``, (runs, sensors) its lag-1 autocovariance relative to the level, and
    (runs, sensors) a usable mask.  The shared part is the mean of the other sensors
    among ``shared_by`` (positions in the used channels; default all)."""
    used = list(rec.channels_used)
    n = len(used)
    runs = [r[SKIP:] for r in replay.runs(rec) if r.size >= MIN_RUN + SKIP]
    if not runs or n < 3:
        return np.empty((0, len(LAGS), n)), np.empty((0, n)), np.empty((0, n), bool)
    ref = np.zeros(n, bool)
    ref[list(range(n)) if shared_by is None else list(shared_by)] = True
    # every run at once: sums within runs by reduceat from each run's first row
    sizes = np.array([r.size for r in runs])
    starts = np.r_[0, np.cumsum(sizes)[:-1]]
    y = rec.readings[np.concatenate(runs)][:, used].astype(np.float64)
    level = np.add.reduceat(y, starts, axis=0) / sizes[:, None]
    y -= np.repeat(level, sizes, axis=0)
    total = y[:, ref].sum(axis=1, keepdims=True)
    count = ref.sum() - ref                          # the others among ``shared_by``
    others = (total - y * ref) / np.maximum(count, 1)
    with np.errstate(invalid='ignore', divide='ignore'):
        beta = np.add.reduceat(y * others, starts, axis=0) / \
            np.add.reduceat(others * others, starts, axis=0)
    e = y - np.repeat(np.nan_to_num(beta), sizes, axis=0) * others
    den = np.add.reduceat(e * e, starts, axis=0)
    good = (den > 0) & (level > MIN_LEVEL)
    left = np.repeat(sizes, sizes) - (np.arange(y.shape[0]) - np.repeat(starts, sizes))
    lagged = []
    for k in LAGS:                  # products within a run only: partners k rows on
        product = np.zeros_like(e)
        np.multiply(e[:-k], e[k:], out=product[:-k], where=(left[:-k] > k)[:, None])
        lagged.append(np.add.reduceat(product, starts, axis=0))
    with np.errstate(invalid='ignore', divide='ignore'):
        a = np.stack(lagged, axis=1) / den[:, None, :]
        c = lagged[0] / (sizes - 1)[:, None] / np.square(level)
    return np.where(good[:, None, :], a, np.nan), np.where(good, c, np.nan), good


def _pooled(recs, shared_by=None, memo=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    parts = [_own(rec, shared_by, memo) for rec in recs]
    return tuple(np.concatenate([p[i] for p in parts]) for i in range(3))


def excess(real: list, sim: list, shared_by=None, memo=None) -> dict:
    """{sensor: {'z', 'p' (of the mean over ``LAGS``), 'acf' {lag: real - simulated},
    'sd' (the wander's sd as a fraction of the level, from the excess lag-1
    autocovariance)}} of every sensor in the stationary recordings ``real`` against
    their replays ``sim``."""
    if not real or not sim:
        return {}
    used = list(real[0].channels_used)
    (ar, cr, okr), (as_, cs, oks) = _pooled(real, shared_by, memo), _pooled(sim, shared_by)
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


def wandering(real: list, sim: list, memo=None) -> dict:
    """The sensors of ``excess`` whose own part is more autocorrelated than simulated
    (one-sided, Holm over the sensors tested at ``ALPHA``).

    The mean of the others carries their wanders into a steady sensor's own part (1/(n-1)
    of each), so the sensors are taken one at a time: the most significant is called
    wandering and left out of the shared part, and the rest tested again, while two or
    more remain to make the shared part from (two that are both significant are both
    called wandering: with no steady sensor left, each carries the other's wander)."""
    if not real:
        return {}
    used = list(real[0].channels_used)
    shared_by, found = list(range(len(used))), {}
    while len(shared_by) >= 2:
        ex = excess(real, sim, shared_by, memo)
        left = _significant({s: v for s, v in ex.items() if used.index(s) in shared_by})
        if not left:
            break
        if len(shared_by) == 2 and len(left) == 2:     # no steady sensor left to tell
            found.update(left)
            break
        top = max(left, key=lambda s: left[s]['z'])
        found[top] = left[top]
        shared_by.remove(used.index(top))
    return dict(sorted(found.items()))


def _significant(ex: dict) -> dict:
    sensors = sorted(ex)
    if not sensors:
        return {}
    adjusted = holm(np.array([ex[s]['p'] for s in sensors]))
    return {s: ex[s] for s, q in zip(sensors, adjusted) if q < ALPHA}


def of_target(target) -> dict:
    """``wandering`` of a fitting target's stationary recordings against its simulator
    (with the effects it is given)."""
    real = target.of_kind('stationary')
    if not real:
        return {}
    # the target's recordings do not change: their own parts are remembered with it
    return wandering(real, target.simulate(kinds=('stationary',)), target.own_parts)
