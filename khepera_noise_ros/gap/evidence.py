"""Measurements that locate an effect, real recordings against their replays: shared fast or
slow noise (group evidence), own wanders, a shared change, the spread by light level."""
from __future__ import annotations

from typing import Any, Callable, Sequence

import numpy as np
from scipy import stats as sps

from ..effects.base import AnyArray, Array, Row
from ..effects.fitting import ALPHA, holm
from ..recording import Recording
from .protocol import runs
from .stationary import own_part

Rows = Callable[[str], list[Row]]     # a comparison's statistics of one family
Parts = list[tuple[AnyArray, ...]]     # ``Own.parts`` of several recordings
Cuts = Sequence[list[np.ndarray]]     # each recording's ``runs``, where known
WINDOW = 8                    # samples averaged into one value of the slow part
CORRELATIONS = ('loop_still_correlation', 'loop_residual_correlation', 'loop_change_correlation')
LOOP_SPREADS = ('loop_still_spread', 'loop_residual_spread', 'loop_change_spread')
OWN_LAGS, OWN_SKIP, OWN_RUN = (1, 3, 10), 3, 24
MIN_LEVEL = 20.0              # readings; darker cells carry no usable ratio or own part
CHANGE_ALPHA, MIN_SENSORS, MIN_CHANGE, MIN_RUNS = 0.001, 3, 0.005, 4


# -- groups ----------------------------------------------------------------------------

def part_sums(recs: Sequence[Recording], part: str, cuts: Cuts) -> dict[str, list[Any]]:
    """{condition: [cross-product matrix, count]} of the 'fast' or 'slow' part of the run
    residuals, pooled over ``recs``."""
    out: dict[str, list[Any]] = {}
    for rec, cut in zip(recs, cuts):
        mine: dict[str, list[Any]] = {}
        for r in cut:
            y = rec.readings[r][:, list(rec.channels_used)].astype(np.float64)
            if part == 'fast':
                d = np.diff(y, axis=0)
            else:
                k = y.shape[0] // WINDOW
                d = (y[:k * WINDOW] - y.mean(axis=0)).reshape(k, WINDOW, y.shape[1]).mean(axis=1)
            if d.shape[0] < 2:
                continue
            d = d - d.mean(axis=0) if part == 'fast' else d
            _add(mine, str(rec.condition[r[0]]), d.T @ d, d.shape[0])
        for cond, (s, n) in mine.items():
            _add(out, cond, s, n)
    return out


def _add(sums: dict[Any, list[Any]], cell: Any, s: Array, n: int) -> None:
    """Adds sums ``s`` of ``n`` rows to ``sums[cell]`` ([sum, count])."""
    acc = sums.setdefault(cell, [0.0, 0])
    acc[0] = acc[0] + s
    acc[1] += n


def part_evidence(real: Sequence[Recording], sim: Sequence[Recording], channels: int,
                  part: str, cuts: tuple[Cuts, Cuts]) -> Array:
    """(C, C) z of real against simulated correlation of the ``part``, Stouffer over
    conditions (0 on the diagonal)."""
    zsum, count = np.zeros((channels, channels)), np.zeros((channels, channels))
    pooled = [part_sums(recs, part, c) for recs, c in zip((real, sim), cuts)]
    for cond, (sr, nr) in pooled[0].items():
        if cond not in pooled[1] or nr < 8:
            continue
        ss, ns = pooled[1][cond]
        se = np.sqrt(1.0 / max(nr - 3, 1) + 1.0 / max(ns - 3, 1))
        with np.errstate(invalid='ignore'):
            z = (_fisher(sr) - _fisher(ss)) / se
        ok = np.isfinite(z)
        zsum += np.where(ok, z, 0.0)
        count += ok
    out = _stouffer(zsum, count)
    np.fill_diagonal(out, 0.0)
    return out


def _fisher(s: Array) -> Array:
    """Fisher's z of the correlations of cross products ``s``, short of +-1."""
    d = np.sqrt(np.clip(np.diag(s), 1e-12, None))
    out: Array = np.arctanh(np.clip(s / d[:, None] / d[None, :], -0.999, 0.999))
    return out


def _stouffer(zsum: Array, count: Array) -> Array:
    with np.errstate(invalid='ignore', divide='ignore'):
        out: Array = np.where(count > 0, zsum / np.sqrt(count), 0.0)
    return out


def combined(rows: Sequence[tuple[tuple[int, ...], float]], channels: Sequence[int]) -> Array:
    """(C, C) Stouffer-combined z of pair rows (sensors, z)."""
    channels = list(channels)
    zsum, count = np.zeros((len(channels),) * 2), np.zeros((len(channels),) * 2)
    for sensors, z in rows:
        if np.isfinite(z) and all(s in channels for s in sensors):
            a, b = (channels.index(s) for s in sensors)
            for i, j in ((a, b), (b, a)):
                zsum[i, j] += z
                count[i, j] += 1
    return _stouffer(zsum, count)


def loop_group_evidence(rows: Rows, channels: Sequence[int], part: str) -> Array:
    """Group evidence of a closed-loop comparison (``rows`` of a family): its stationary
    correlations if any, else (fast part) its noise correlations (the change view only
    where no direct view is)."""
    z = combined([(r.key.sensors, r.z) for r in rows('correlation')], channels)
    if part != 'fast' or z.any():
        return z
    families = [f for f in CORRELATIONS[:2] if rows(f)] or list(CORRELATIONS)
    return combined([(r.key.sensors, r.z) for f in families for r in rows(f)], channels)


def correlation_evidence(keys: Sequence[Any], estimate: Array, se: Array,
                         channels: Sequence[int]) -> Array:
    """(C, C) z of correlations against zero (real data alone), Stouffer over conditions."""
    return combined([(k.sensors, v / s if s > 0 else 0.0) for k, v, s in zip(keys, estimate, se)
                     if k.family == 'correlation' and np.isfinite(v) and np.isfinite(s)], channels)


# -- spreads ---------------------------------------------------------------------------

def spread_cells(rows: Rows, level: dict[tuple[Any, ...], float], sensors: Sequence[int],
                 closed_loop: bool) -> list[tuple[float, float]]:
    """[(level, real minus simulated variance)] of ``sensors``: each stationary cell at its
    simulated level (unless ``closed_loop``), then the closed loop's still view per level
    band (at the band's middle) and its residual view per sensor at its real mean level
    (``level``: closed_loop_level by (sensors, condition)); the change view only where
    neither exists (its regression takes part of the noise too)."""
    out = []
    if not closed_loop:
        sim_level = {r.key[1:]: r.sim for r in reversed(rows('level'))}   # (sensors, cell)
        out += [(sim_level[r.key[1:]], r.real ** 2 - r.sim ** 2) for r in rows('spread')
                if r.key.sensors[0] in sensors and r.key[1:] in sim_level]
    loop = [r for f in LOOP_SPREADS for r in rows(f)]
    direct = [r for r in loop if r.key.family != 'loop_change_spread']
    for r in direct or loop:
        if r.key.sensors[0] not in sensors or not (np.isfinite(r.real) and np.isfinite(r.sim)):
            continue
        excess = r.real * r.real - r.sim * r.sim
        if r.key.family != 'loop_residual_spread':
            lo, hi = (float(v) for v in str(r.key.part).split()[1].split('-'))
            out.append(((lo + hi) / 2, excess))
        elif (r.key.sensors, r.key.condition) in level:
            out.append((level[(r.key.sensors, r.key.condition)], excess))
    return out


# -- own wander ------------------------------------------------------------------------

class Own:
    """A recording's run residuals for ``parts``: the same whichever sensors share."""

    def __init__(self, rec: Recording, cut: list[np.ndarray] | None = None):
        used = list(rec.channels_used)
        self.n = len(used)
        kept = [r[OWN_SKIP:] for r in (runs(rec) if cut is None else cut)
                if r.size >= OWN_RUN + OWN_SKIP]
        self.sizes = sizes = np.array([r.size for r in kept], np.int64)
        if not kept or self.n < 3:
            return
        self.starts = starts = np.r_[0, np.cumsum(sizes)[:-1]]
        self.y = rec.readings[np.concatenate(kept)][:, used].astype(np.float64)
        self.level = np.add.reduceat(self.y, starts, axis=0) / sizes[:, None]
        self.y -= np.repeat(self.level, sizes, axis=0)
        self.left = np.repeat(sizes, sizes) - (np.arange(len(self.y)) - np.repeat(starts, sizes))
        self.run = np.repeat(np.arange(sizes.size), sizes)

    def parts(self, shared_by: Sequence[int] | None = None) -> tuple[AnyArray, ...]:
        """Over runs: (runs, lags, sensors) autocorrelation of each sensor's own part,
        (runs, sensors) its lag-1 autocovariance over the squared level, a usable mask.  The
        shared part is the mean of the others among ``shared_by`` (positions; default all)."""
        n, sizes = self.n, self.sizes
        if not sizes.size or n < 3:
            return np.empty((0, len(OWN_LAGS), n)), np.empty((0, n)), np.empty((0, n), bool)
        ref = np.ones(n, bool) if shared_by is None else np.isin(np.arange(n), shared_by)
        starts, y, level, left = self.starts, self.y, self.level, self.left
        e = own_part(y, ref, lambda v: np.add.reduceat(v, starts, axis=0), self.run)
        den = np.add.reduceat(e * e, starts, axis=0)
        good = (den > 0) & (level > MIN_LEVEL)
        lagged = []
        for k in OWN_LAGS:                  # products within a run only: partners k rows on
            product = np.zeros_like(e)
            np.multiply(e[:-k], e[k:], out=product[:-k], where=(left[:-k] > k)[:, None])
            lagged.append(np.add.reduceat(product, starts, axis=0))
        with np.errstate(invalid='ignore', divide='ignore'):
            a = np.stack(lagged, axis=1) / den[:, None, :]
            c = lagged[0] / (sizes - 1)[:, None] / np.square(level)
        return np.where(good[:, None, :], a, np.nan), np.where(good, c, np.nan), good


def own_excess(real: Parts, sim: Parts, used: list[int]) -> dict[int, dict[str, Any]]:
    """{sensor: {z, p, acf {lag: real - simulated}, sd}} from pooled ``Own.parts``."""
    (ar, cr, okr), (as_, cs, oks) = ([np.concatenate(c) for c in zip(*parts)]
                                     for parts in (real, sim))
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
                  'acf': {lag: float(v) for lag, v in zip(OWN_LAGS, lags)},
                  'sd': float(np.sqrt(max(extra, 0.0)))}
    return out


def wandering(parts: Callable[[tuple[int, ...]], tuple[Parts, Parts]],
              used: list[int]) -> dict[int, dict[str, Any]]:
    """The sensors whose own part is more autocorrelated than simulated (Holm at
    ``ALPHA``), found one at a time: the most significant is taken out of the shared part
    (the mean of the others carries their wanders into a steady sensor's own part) and the
    rest tested again while two remain.  ``parts(shared_by)``: (real, simulated) own parts."""
    shared_by, found = list(range(len(used))), {}
    while len(shared_by) >= 2:
        ex = own_excess(*parts(tuple(shared_by)), used)
        mine = {s: v for s, v in ex.items() if used.index(s) in shared_by}
        sensors = sorted(mine)
        adjusted = holm(np.array([mine[s]['p'] for s in sensors])) if sensors else np.zeros(0)
        left = {s: mine[s] for s, q in zip(sensors, adjusted) if q < ALPHA}
        if not left:
            break
        if len(shared_by) == 2 and len(left) == 2:     # no steady sensor left to tell
            found.update(left)
            break
        top = max(left, key=lambda s: left[s]['z'])
        found[top] = left[top]
        shared_by.remove(used.index(top))
    return dict(sorted(found.items()))


# -- shared change -------------------------------------------------------------------

def _cell(rec: Recording, r: np.ndarray) -> tuple[str, float]:
    return str(rec.condition[r[0]]), float(np.round(rec.heading_deg[r[0]], 1))


def _factors(rec: Recording, cut: list[np.ndarray], reference: dict[Any, Array],
             sensors: list[int]) -> list[Any]:
    """[(run, cell, run means, simulated levels, white variance of the run means)]."""
    out = []
    for r in cut:
        ref = reference.get(_cell(rec, r))
        if ref is None or r.size < 2:
            continue
        x = rec.readings[r][:, sensors].astype(np.float64)
        mean = x.mean(axis=0)
        if ((ref > MIN_LEVEL) & np.isfinite(mean)).sum() >= MIN_SENSORS:
            fast = np.diff(x, axis=0).mean(axis=1)       # the part all sensors share
            out.append((r, _cell(rec, r), mean, ref, float(np.mean(fast * fast)) / 2 / r.size))
    return out


def _shared(rows: list[Any], rounds: int = 3) -> Array:
    """Each run's shared factor with each sensor's calibration line (a + b level) taken out:
    factors and lines fitted in turn, the factors' geometric mean 1; ``rounds`` 1: the
    plain median ratios."""
    mean = np.array([row[2] for row in rows])
    ref = np.array([row[3] for row in rows])
    ok = (ref > MIN_LEVEL) & np.isfinite(mean)
    a, b = np.zeros(mean.shape[1]), np.ones(mean.shape[1])
    factor = np.ones(len(rows))
    for _ in range(rounds):
        line = a + b * ref
        with np.errstate(invalid='ignore', divide='ignore'):
            ratio = np.where(ok & (line > 0), mean / line, np.nan)
        factor = np.nanmedian(ratio, axis=1)
        if rounds > 1:
            factor = factor / np.exp(np.mean(np.log(factor)))
        for s in range(mean.shape[1]):
            use = ok[:, s]
            if use.sum() >= MIN_RUNS and np.ptp(ref[use, s]) >= 1.0:
                b[s], a[s] = np.polyfit(ref[use, s], mean[use, s] / factor[use], 1)
    return factor


def shared_change(real: Sequence[Recording], sim: Sequence[Recording], sensors: list[int],
                  cuts: tuple[Cuts | None, Cuts | None] = (None, None)) -> dict[str, Any] | None:
    """{p_value, ratio, excess_sd, significant, runs: [(run, factor)] per real recording,
    sd} of a change over time shared by the sensors, or None with no way to tell."""
    if not real or not sim:
        return None
    real_cuts, sim_cuts = (c or [runs(rec) for rec in recs] for recs, c in zip((real, sim), cuts))
    acc: dict[Any, list[Array]] = {}
    for rec, cut in zip(sim, sim_cuts):
        for r in cut:
            acc.setdefault(_cell(rec, r), []).append(rec.readings[r][:, sensors])
    reference = {cell: np.concatenate(v).mean(axis=0) for cell, v in acc.items()}
    rows_real = [_factors(rec, cut, reference, sensors) for rec, cut in zip(real, real_cuts)]
    rows_sim = [row for rec, cut in zip(sim, sim_cuts)
                for row in _factors(rec, cut, reference, sensors)]
    flat = [row for rows in rows_real for row in rows]
    if len(flat) < 3 or len(rows_sim) < 3:
        return None
    logs = [np.log(_shared(rows)) for rows in (flat, rows_sim)]
    (v_real, v_sim), (d_real, d_sim) = [float(np.var(v, ddof=1)) for v in logs], \
        [v.size - 1 for v in logs]
    if d_real < 2 or d_sim < 2 or v_sim <= 0:
        return None
    fast = [float(np.mean([row[4] for row in rows] / np.square(
        [np.mean(row[2][(row[3] > MIN_LEVEL) & np.isfinite(row[2])]) for row in rows])))
        for rows in (flat, rows_sim)]
    expected = v_sim + max(fast[0] - fast[1], 0.0)
    p = float(sps.f.sf(v_real / expected, d_real, d_sim))
    excess = float(np.sqrt(max(v_real - expected, 0.0)))
    plain = _shared(flat, rounds=1)     # where a condition has one run, lines absorb a change
    per_rec = np.split(plain, np.cumsum([len(rows) for rows in rows_real])[:-1])
    runs_ = [[(row[0], float(f)) for row, f in zip(rows, factors)]
             for rows, factors in zip(rows_real, per_rec)]
    return {'p_value': p, 'ratio': float(v_real / expected), 'excess_sd': excess,
            'significant': p < CHANGE_ALPHA and excess >= MIN_CHANGE, 'runs': runs_,
            'sd': float(np.std(plain))}


def steady_rows(rows: list[Row], real: Sequence[Recording], change: dict[str, Any]) -> list[Row]:
    """Level rows whose real levels come from the readings with each run divided by its
    shared factor."""
    sums: dict[tuple[str, str | None], list[Any]] = {}
    for rec, runs_ in zip(real, change['runs']):
        x = rec.readings.astype(np.float64)
        for r, f in runs_:
            cond, h = _cell(rec, r)
            _add(sums, (cond, f'heading {h:g} deg' if np.isfinite(h) else None),
                 (x[r] / f).sum(axis=0), r.size)
    out = []
    for row in rows:
        found = sums.get((str(row.key.condition), row.key.part))
        if found is not None:
            real_level = float(found[0][row.key.sensors[0]] / found[1])
            row = row._replace(real=real_level, z=(real_level - row.sim) / row.se)
        out.append(row)
    return out
