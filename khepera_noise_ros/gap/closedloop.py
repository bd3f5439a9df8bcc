"""The statistics of closed-loop recordings from per-episode sums: levels, fitness factors,
turn responses and scatter, and the noise while turning in three views (docs/diagnosis.md)."""
from __future__ import annotations

import functools
from typing import Callable

import numpy as np
from scipy import sparse

from ..core.task import fitness_factors
from ..effects.base import AnyArray, Array, Key
from ..recording import Recording
from . import bootstrap
from .protocol import ordered

FACTORS = ('balance', 'intensity', 'turning')
BANDS = (0.0, 175.0, 350.0)          # lower edges of the noise's level bands (readings)
POWER_BANDS = ((0, 0), (1, 5), (6, 9))
MIN_ROWS = 8                         # rows a statistic needs in the full data
QUIET = 350.0                        # the change view's pairs: rows where both read dark
QUIET_PART = f'readings >= {QUIET:g}'
CHANGE_LAGS = 4                      # commands u(t) .. u(t - 3): a latency up to 3 steps
DELAYS = (0, 1, 2, 3)                # delays the residual view tries
HEADING_BIN, BIN_DENSITY, REGRESSORS, CLEAR = 10.0, 0.5, 5, 0.9


def blocks(rec: Recording, x: Array, more: Callable[..., dict[str, Array]], perturb_every: int,
           loop_only: bool = False) -> bootstrap.Blocks:
    """Per-episode sums of a closed-loop recording (repaired readings ``x``); with
    ``loop_only`` (no stationary recording beside it) the change view and the value
    lattice too."""
    episodes, ep, order, steps, pair = ordered(rec)
    m = episodes.size
    r = x[order][:, :8].astype(np.float64)
    u = rec.direction[order] * rec.power[order]
    heading = rec.heading_deg[order]
    tracked = bool(np.isfinite(heading).all())
    phase = (steps % perturb_every)[:, None] == np.arange(perturb_every)[None, :]
    by = functools.partial(sum_by, ep, episodes=m)
    factors = np.stack(fitness_factors(r, rec.power[order]), axis=1).astype(np.float64)
    parts = {'n': by(np.ones((len(r), 1))), 'level': by(r),
             'factor': by(factors[:, :, None] * phase[:, None, :]), 'phase_n': by(phase * 1.0),
             'power': by(rec.power[order][:, None] * phase),
             'right': by((rec.direction[order] > 0)[:, None] * 1.0)}
    # the turn regression: rows j with j - 1, j, j + 1 consecutive and j + 1 no knock (the
    # knock, not the command, moves the heading there)
    after = np.r_[pair[1:], False] & (np.r_[steps[1:], 0] % perturb_every != 0)
    ok = np.flatnonzero(pair & after)
    xr = np.stack([u[ok], u[ok - 1], np.ones(ok.size)], axis=1)
    dr = r[ok + 1] - r[ok]
    front = imbalance(r)
    dy = front[ok + 1] - front[ok]
    e = ep[ok]
    parts['xtx'] = _gram(e, xr, xr, m)
    parts['xty'] = sum_by(e, xr * dy[:, None], m)
    parts['xty_sensor'] = _gram(e, xr, dr, m)
    design = np.concatenate([u[ok, None], u[ok - 1, None], np.ones((ok.size, 1)), r[ok],
                             u[ok, None] * r[ok] / 100.0], axis=1)
    w = _bands(u[ok])
    parts['scatter_n'] = sum_by(e, w, m)
    inside = w.any(axis=1)             # each row in its band's group only
    band = e[inside] * w.shape[1] + w[inside].argmax(axis=1)
    for name, y in (('xx', design), ('xy', dr)):
        parts[f'scatter_{name}'] = _gram(band, design[inside], y[inside], m * w.shape[1]) \
            .reshape(m, w.shape[1], design.shape[1], -1)
    parts['scatter_yy'] = sum_by(e, w * (dr * dr).sum(axis=1)[:, None], m)
    if tracked:           # the turn itself, per band: n, u^2, u dh, dh^2
        t = np.flatnonzero(after)
        dh = wrap(heading[t + 1] - heading[t])
        moments = np.stack([np.ones(t.size), u[t] ** 2, u[t] * dh, dh * dh], axis=1)
        parts['heading_band'] = sum_by(ep[t], _bands(u[t])[:, :, None] * moments[:, None, :], m)
    power = np.nan_to_num(rec.power[order], nan=1.0)
    still = pair & np.r_[False, power[:-1] == 0] & (steps % perturb_every != 0)
    d, level = np.zeros_like(r), np.zeros_like(r)
    d[1:], level[1:] = r[1:] - r[:-1], (r[1:] + r[:-1]) / 2
    parts.update(_view('still', d, _onehot(level, still), still,
                       still & np.r_[False, still[:-1]], ep, m, 0.5))  # var(d) = 2 var(noise)
    # the change view stands in for the residual view on a robot nobody tracked; a
    # simulated side always knows its headings: it gives both, the real side chooses
    if loop_only and (not tracked or rec.manifest.get('source') == 'simulator'):
        parts.update(_change_parts(rec, order, ep, m, steps, pair, r, power, perturb_every))
    if tracked:
        res, use, _ = residuals(r, heading, rec.condition[order], pair, m)
        parts.update(_view('res', res, None, use, use & pair & np.r_[False, use[:-1]], ep, m,
                           1.0))
    parts.update(more(order, ep, m))          # the converter's sums
    conditions = rec.conditions()
    first = rec.condition[order][np.r_[0, np.flatnonzero(np.diff(ep)) + 1]]
    stratum = np.array([conditions.index(str(c)) for c in first], np.int64)
    table, layout = bootstrap.pack(parts)
    return bootstrap.Blocks('closed_loop', tuple(range(8)), conditions, stratum, table, layout,
                            {'perturb_every': perturb_every, 'heading': tracked})


def sum_by(ep: np.ndarray, values: AnyArray, episodes: int) -> Array:
    """(episodes, ...) sums of ``values`` by the sorted ``ep``: one sparse product."""
    n = ep.size
    indptr = np.searchsorted(ep, np.arange(episodes + 1))
    pick = sparse.csr_matrix((np.ones(n), np.arange(n), indptr), shape=(episodes, n))
    out: Array = np.asarray(pick @ values.reshape(n, -1), np.float64)
    return out.reshape((episodes,) + values.shape[1:])


def imbalance(r: Array) -> Array:
    """Left (sensors 0-2) less right (3-5) mean front reading: what a turn answers."""
    out: Array = r[:, 0:3].mean(axis=1) - r[:, 3:6].mean(axis=1)
    return out


def wrap(deg: Array) -> Array:
    """Angles in degrees wrapped to [-180, 180)."""
    out: Array = (deg + 180.0) % 360.0 - 180.0
    return out


def _gram(group: np.ndarray, a: Array, b: Array, groups: int) -> Array:
    """(groups, ka, kb) sums of the outer products of the rows of ``a`` and ``b`` by group,
    one matrix product per group (never the (N, ka, kb) products)."""
    if not np.all(group[1:] >= group[:-1]):
        order = np.argsort(group, kind='stable')
        group, a, b = group[order], a[order], b[order]
    out = np.zeros((groups, a.shape[1], b.shape[1]))
    bounds = np.searchsorted(group, np.arange(groups + 1))
    for g in np.flatnonzero(bounds[1:] > bounds[:-1]):
        rows = slice(bounds[g], bounds[g + 1])
        out[g] = a[rows].T @ b[rows]
    return out


def _bands(u: Array) -> Array:
    """(N, 3) one-hot band of each command's |power|."""
    p = np.abs(np.rint(u))
    return np.stack([(p >= lo) & (p <= hi) for lo, hi in POWER_BANDS], axis=1).astype(np.float64)


def _onehot(level: Array, use: np.ndarray) -> Array:
    band = np.searchsorted(np.array(BANDS), level, side='right') - 1
    out: Array = (band[:, None, :] == np.arange(len(BANDS))[None, :, None]) & use[:, None, None]
    return out


def _view(name: str, x: Array, onehot: Array | None, use: np.ndarray, lagged: np.ndarray,
          ep: np.ndarray, m: int, scale: float) -> dict[str, Array]:
    """Per-episode count, cross products, per-band counts and squares, and lag-1 products
    (``lagged``: t whose t - 1 is used too) of ``x``."""
    xs = x * use[:, None]
    lag = np.zeros_like(x)
    lag[1:] = x[1:] * x[:-1]
    out = {f'{name}_n': sum_by(ep, use[:, None] * 1.0, m),
           f'{name}_s2': scale * _gram(ep, xs, xs, m),
           f'{name}_lag_n': sum_by(ep, lagged[:, None] * 1.0, m),
           f'{name}_lag_s': scale * sum_by(ep, lag * lagged[:, None], m)}
    if onehot is not None:
        out[f'{name}_band_n'] = sum_by(ep, onehot * 1.0, m)
        out[f'{name}_band_s2'] = scale * sum_by(ep, onehot * (xs * xs)[:, None, :], m)
    return out


def _change_parts(rec: Recording, order: np.ndarray, ep: np.ndarray, m: int, steps: np.ndarray,
                  pair: np.ndarray, r: Array, power: Array,
                  perturb_every: int) -> dict[str, Array]:
    """The change view: residuals of each sensor's next change on the commands u(t - j)
    and their products with every reading, fitted per condition."""
    u = np.nan_to_num(rec.direction[order], nan=0.0) * power
    t = np.arange(CHANGE_LAGS - 1, len(ep) - 1)
    back = t - CHANGE_LAGS + 1
    rows = t[(ep[t + 1] == ep[back]) & (steps[t + 1] - steps[back] == CHANGE_LAGS)
             & (steps[t + 1] % perturb_every != 0)]
    e, use = np.zeros_like(r), np.zeros(len(r), bool)
    condition = rec.condition[order]
    for cond in np.unique(condition):
        at = rows[condition[rows] == cond]
        if at.size > 2 * (CHANGE_LAGS + 4):
            commands = np.stack([u[at - j] for j in range(CHANGE_LAGS)], axis=1)
            design = np.concatenate([np.ones((at.size, 1)), commands, (
                commands[:, :, None] * (r[at] / 100.0)[:, None, :]).reshape(at.size, -1)],
                axis=1)
            change = r[at + 1] - r[at]
            beta, *_ = np.linalg.lstsq(design, change, rcond=None)
            e[at], use[at] = change - design @ beta, True
    quiet = (r >= QUIET) & use[:, None]
    eq = e * quiet
    both = quiet[:, :, None] & quiet[:, None, :]
    lagged = quiet & pair[:, None]
    lagged[1:] &= quiet[:-1]
    lag = np.zeros_like(e)
    lag[1:] = e[1:] * e[:-1]
    onehot = _onehot(r, use)
    return {'chg_band_n': sum_by(ep, onehot * 1.0, m),
            'chg_band_s2': 0.5 * sum_by(ep, onehot * (e * e)[:, None, :], m),
            'chg_q_n': sum_by(ep, both * 1.0, m),
            'chg_q_xy': 0.5 * _gram(ep, eq, eq, m),
            'chg_q_xx': 0.5 * sum_by(ep, (eq * eq)[:, :, None] * both, m),
            'chg_lag_n': sum_by(ep, lagged * 1.0, m),
            'chg_lag_s': 0.5 * sum_by(ep, lag * lagged, m)}


# -- the residual view's delays --------------------------------------------------------------

def residuals(r: Array, heading: Array, condition: np.ndarray, pair: np.ndarray,
              episodes: int) -> tuple[Array, np.ndarray, np.ndarray]:
    """(residuals (N, 8) scaled to their cells' degrees of freedom, usable rows, delay per
    sensor): each sensor keeps the delay whose design leaves a tenth less variance than
    the undelayed one (on rows every design can use), else no delay."""
    fits, var = delay_fits(r, heading, condition, pair, episodes)
    if var is None:
        return np.zeros_like(r), np.zeros(len(r), bool), np.zeros(r.shape[1], np.int64)
    lag = np.where(var[1:].min(axis=0) < CLEAR * var[0], np.argmin(var, axis=0), 0)
    e = np.stack([fits[lag[k]][0][:, k] for k in range(r.shape[1])], axis=1)
    use = np.logical_and.reduce([fits[j][1] for j in np.unique(lag)])
    return np.where(use[:, None], e, 0.0), use, np.asarray(DELAYS)[lag]


def delay_fits(r: Array, heading: Array, condition: np.ndarray, pair: np.ndarray,
               episodes: int) -> tuple[list[tuple[Array, np.ndarray]], Array | None]:
    """(per delay: residuals and usable rows; (delays, 8) variance on the common rows)."""
    _, cond = np.unique(condition, return_inverse=True)
    h = np.mod(heading + 180.0, 360.0)
    have = [pair.copy()]                     # have[j]: j + 1 earlier steps in the episode
    for j in range(1, max(DELAYS) + 1):
        have.append(have[-1] & np.r_[np.zeros(j, bool), pair[:-j]])
    fits = [_fit(r, h, cond, have[max(lag, 1)], lag, episodes) for lag in DELAYS]
    common = np.logical_and.reduce([ok for _, ok in fits])
    if not common.any():
        return fits, None
    return fits, np.stack([np.mean(e[common] ** 2, axis=0) for e, _ in fits])


def _fit(r: Array, h: Array, cond: np.ndarray, have: np.ndarray, lag: int,
         episodes: int) -> tuple[Array, np.ndarray]:
    """The design at delay ``lag``: per (condition, bin of h(t - lag)) a quadratic in that
    heading and the turns to its neighbours (at 0: to h(t - 1) and h(t - 2))."""
    at = _shift(h, lag)
    _, cell = np.unique(cond * 1000 + np.floor(at / HEADING_BIN).astype(np.int64),
                        return_inverse=True)
    n = np.bincount(cell, have.astype(np.float64))
    hc = at - (np.bincount(cell, have * at) / np.maximum(n, 1))[cell]
    near = (lag + 1, lag + 2) if lag == 0 else (lag + 1, lag - 1)
    turns = [wrap(_shift(h, j) - at) for j in near]
    x = np.stack([np.ones_like(h), hc, hc * hc] + turns, axis=1)
    use = have & (n[cell] >= max(BIN_DENSITY * episodes, REGRESSORS + 2))
    cells, w = int(cell.max()) + 1, use.astype(np.float64)
    xw = x * w[:, None]
    xx, xr = _gram(cell, xw, x, cells), _gram(cell, xw, r, cells)
    scale = np.trace(xx, axis1=-2, axis2=-1)[..., None, None] + 1e-12
    beta = np.linalg.solve(xx + 1e-10 * scale * np.eye(REGRESSORS), xr)
    e = r - np.einsum('ni,nik->nk', x, beta[cell])
    count = np.bincount(cell, w, minlength=cells)
    with np.errstate(divide='ignore', invalid='ignore'):
        inflate = np.where(count > REGRESSORS, np.sqrt(count / (count - REGRESSORS)), 0.0)
    return np.where(use[:, None], e * inflate[cell][:, None], 0.0), use


def _shift(h: Array, lag: int) -> Array:
    out: Array = np.r_[np.zeros(lag), h[:h.size - lag]]
    return out


def delayed_sensors(recordings: list[Recording]) -> tuple[int, ...]:
    """The sensors a latency may act on, from tracked closed-loop recordings: all but those
    clearly read at the heading of the moment; none when no sensor clearly reads an
    earlier heading."""
    late, now = np.zeros(8, bool), np.zeros(8, bool)
    for rec in recordings:
        if not np.isfinite(rec.heading_deg).all():
            continue
        episodes, _, order, _, pair = ordered(rec)
        _, var = delay_fits(rec.readings[order][:, :8].astype(np.float64),
                            rec.heading_deg[order], rec.condition[order], pair, episodes.size)
        if var is not None:
            late |= var[1:].min(axis=0) < CLEAR * var[0]
            now |= var[0] < CLEAR * var[1:].min(axis=0)
    return tuple(int(k) for k in np.flatnonzero(~now)) if late.any() else ()


# -- statistics ------------------------------------------------------------------------------

Part = Callable[[bootstrap.Blocks, Array, int, str], tuple[list[Key], list[Array]]]
Columns = list[tuple[Key, Array]]
LEVELS = tuple(f'level {lo:g}-{hi:g}' for lo, hi in zip(BANDS, BANDS[1:] + (525.0,)))
PAIRS = tuple((k, m) for k in range(8) for m in range(k + 1, 8))


def stats(b: bootstrap.Blocks, s: Array, more: Part) -> tuple[list[Key], list[Array]]:
    """(keys, columns) from the resampled (R, S, D) per-episode sums; ``more``: the
    converter's statistics of each stratum (its columns may be (R, k) blocks)."""
    keys: list[Key] = []
    cols: list[Array] = []
    n = b.part(s, 'n')[..., 0]
    front = (0, 1, 2, 3, 4, 5)
    lags = ('lag 0', 'lag 1')
    for i, c in enumerate(b.strata):
        level = b.part(s, 'level')[:, i] / n[:, i, None]
        out: Columns = [(Key('closed_loop_level', (k,), c, None), level[:, k]) for k in range(8)]
        factor, count = b.part(s, 'factor')[:, i], b.part(s, 'phase_n')[:, i]
        power = b.part(s, 'power')[:, i] / count
        for p in range(b.extra['perturb_every']):
            part = f'step {p} after perturbation'
            out += [(Key(f'fitness_{name}', front, c, part), factor[:, f, p] / count[:, p])
                    for f, name in enumerate(FACTORS)]
            out.append((Key('turn_power', (), c, part), power[:, p]))
        right = b.part(s, 'right')[:, i, 0] / n[:, i]
        out.append((Key('turn_right_fraction', (), c, None), right))
        xtx = b.part(s, 'xtx')[:, i]
        beta = _solve(xtx, b.part(s, 'xty')[:, i][..., None])[..., 0]
        beta_s = _solve(xtx, b.part(s, 'xty_sensor')[:, i])
        out += [(Key('turn_response', front, c, lag), beta[:, j]) for j, lag in enumerate(lags)]
        out += [(Key('sensor_turn_response', (k,), c, lag), beta_s[:, j, k])
                for k in range(8) for j, lag in enumerate(lags)]
        if b.extra['heading']:
            h = b.part(s, 'heading_band')[:, i].sum(axis=1)
            out.append((Key('turn_size', (), c, 'deg per unit of command'), h[:, 2] / h[:, 1]))
        out += _noise_stats(b, s, i, c) + _change_stats(b, s, i, c) + _scatter_stats(b, s, i, c)
        more_keys, more_cols = more(b, s, i, c)
        keys += [k for k, _ in out] + more_keys
        cols += [v for _, v in out] + more_cols
    return keys, cols


def _noise_stats(b: bootstrap.Blocks, s: Array, i: int, c: str) -> Columns:
    out: Columns = []
    views = [('still', 'still', 'lag 1 of differences')]
    if b.has('res_n'):
        views.append(('residual', 'res', 'lag 1'))
    for view, name, lag_part in views:
        n = b.part(s, f'{name}_n')[:, i, 0]
        if n[0] < MIN_ROWS:
            continue
        cov = b.part(s, f'{name}_s2')[:, i] / n[:, None, None]
        var = np.diagonal(cov, axis1=-2, axis2=-1)
        if name == 'still':
            band_n = b.part(s, 'still_band_n')[:, i]
            spread = np.sqrt(b.part(s, 'still_band_s2')[:, i] / band_n)
            bands = [(label, band_n[:, j], spread[:, j]) for j, label in enumerate(LEVELS)]
        else:      # one spread per sensor: where the light is steep a band is not noise alone
            bands = [('level 0-525', np.repeat(n[:, None], 8, axis=1), np.sqrt(var))]
        out += [(Key(f'loop_{view}_spread', (k,), c, part), sd[:, k])
                for part, count, sd in bands for k in range(8) if count[0, k] >= MIN_ROWS]
        sd = np.sqrt(var)
        corr = cov / (sd[:, :, None] * sd[:, None, :])
        out += [(Key(f'loop_{view}_correlation', pair, c, None), corr[:, pair[0], pair[1]])
                for pair in PAIRS]
        lag_n = b.part(s, f'{name}_lag_n')[:, i, 0]
        if lag_n[0] >= MIN_ROWS:
            lag = b.part(s, f'{name}_lag_s')[:, i] / lag_n[:, None] / var
            out += [(Key(f'loop_{view}_autocorrelation', (k,), c, lag_part), lag[:, k])
                    for k in range(8)]
    return out


def _change_stats(b: bootstrap.Blocks, s: Array, i: int, c: str) -> Columns:
    if not b.has('chg_band_n'):
        return []
    band_n, q_n = b.part(s, 'chg_band_n')[:, i], b.part(s, 'chg_q_n')[:, i]
    xx, lag_n = b.part(s, 'chg_q_xx')[:, i], b.part(s, 'chg_lag_n')[:, i]
    with np.errstate(divide='ignore', invalid='ignore'):
        spread = np.sqrt(b.part(s, 'chg_band_s2')[:, i] / band_n)
        corr = b.part(s, 'chg_q_xy')[:, i] / np.sqrt(xx * np.swapaxes(xx, 1, 2))
        var = np.diagonal(xx, axis1=-2, axis2=-1) / np.diagonal(q_n, axis1=-2, axis2=-1)
        lag = b.part(s, 'chg_lag_s')[:, i] / lag_n / var
    return [(Key('loop_change_spread', (k,), c, label), spread[:, j, k])
            for j, label in enumerate(LEVELS) for k in range(8) if band_n[0, j, k] >= MIN_ROWS] \
        + [(Key('loop_change_correlation', (k, m), c, QUIET_PART), corr[:, k, m])
           for k, m in PAIRS if q_n[0, k, m] >= MIN_ROWS] \
        + [(Key('loop_change_autocorrelation', (k,), c, QUIET_PART), lag[:, k])
           for k in range(8) if lag_n[0, k] >= MIN_ROWS]


def _scatter_stats(b: bootstrap.Blocks, s: Array, i: int, c: str) -> Columns:
    """``turn_scatter``: per power band the readings' change about the pooled regression
    (rms over sensors); with headings ``turn_size_scatter``: the turn about the pooled
    turn per unit of command."""
    n, xx = b.part(s, 'scatter_n')[:, i], b.part(s, 'scatter_xx')[:, i]
    xy, yy = b.part(s, 'scatter_xy')[:, i], b.part(s, 'scatter_yy')[:, i]
    with np.errstate(invalid='ignore'):
        beta = np.linalg.pinv(xx.sum(axis=1), rcond=1e-10, hermitian=True) @ xy.sum(axis=1)
    rss = yy - 2 * np.einsum('rbik,rik->rb', xy, beta) \
        + np.einsum('rik,rbij,rjk->rb', beta, xx, beta)
    labels = [f'power {lo}' if lo == hi else f'power {lo}-{hi}' for lo, hi in POWER_BANDS]
    out = [(Key('turn_scatter', tuple(range(8)), c, label), _rms(rss[:, j], n[:, j] * 8))
           for j, label in enumerate(labels)]
    if b.extra['heading']:
        h = b.part(s, 'heading_band')[:, i]
        total = h.sum(axis=1)
        k = total[:, 2] / total[:, 1]
        out += [(Key('turn_size_scatter', (), c, label),
                 _rms(h[:, j, 3] - 2 * k * h[:, j, 2] + k * k * h[:, j, 1], h[:, j, 0]))
                for j, label in enumerate(labels)]
    return out


def _rms(rss: Array, n: Array) -> Array:
    """Root mean square residual; NaN where a band has fewer than 3 rows."""
    with np.errstate(invalid='ignore', divide='ignore'):
        out: Array = np.where(n >= 3, np.sqrt(np.clip(rss, 0.0, None) / n), np.nan)
    return out


def _solve(a: Array, b: Array) -> Array:
    """Batched least squares that tolerates singular moment matrices (NaN there)."""
    out = np.full(b.shape, np.nan)
    ok = np.abs(np.linalg.det(a)) > 1e-9
    out[ok] = np.linalg.solve(a[ok], b[ok])
    return out
