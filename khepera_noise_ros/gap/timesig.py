"""The time signature of level differences: a shared change over time, or a fixed calibration.

A gain or offset is constant in time; a drift shared by the sensors (the room's light
switched, the supply changed) moves all of them together, from one stretch of the
recording to the next, in steps, a ramp or a wave.  Each run (one episode at one
heading and condition) gives a *shared factor*: the median over the sensors of the
run's mean reading over the simulator's level for the same cell.  Run to run these
factors vary by chance only as much as the simulator's own do; more than that (F
test on their log spread) is a shared change over time.  Sensors are then compared
with the light model after each run is divided by its factor, so a per-sensor gain
or offset is what is left over the shared change, and the shared change is the
drift's.
"""
from __future__ import annotations

import numpy as np
from scipy import stats as sps

from . import replay

ALPHA = 0.001          # the shared factors vary more than simulated at this level
MIN_LEVEL = 20.0       # readings; darker cells than this carry no usable ratio
MIN_SENSORS = 3        # a shared factor needs this many usable sensors
MIN_CHANGE = 0.005     # and a change must move the factors by this sd beyond the simulator's


def _factors(rec, reference: dict, sensors) -> list[tuple]:
    """[(run samples, cell, run means, simulated levels, fast variance of the run means)]
    of a stationary recording against the simulated cell levels ``reference``
    {(condition, heading): level per sensor}; the fast variance (per sensor, first
    differences / 2n) is how much white noise alone moves a run's mean."""
    out = []
    for r in replay.runs(rec):
        cell = (str(rec.condition[r[0]]), float(np.round(rec.heading_deg[r[0]], 1)))
        ref = reference.get(cell)
        if ref is None or r.size < 2:
            continue
        x = rec.readings[r][:, sensors].astype(np.float64)
        mean = x.mean(axis=0)
        ok = (ref > MIN_LEVEL) & np.isfinite(mean)
        if ok.sum() >= MIN_SENSORS:
            fast = np.diff(x, axis=0).mean(axis=1)      # the part all sensors share
            white = float(np.mean(fast * fast)) / 2.0 / r.size
            out.append((r, cell, mean, ref, white))
    return out


def _shared(rows, rounds: int = 3) -> np.ndarray:
    """Each run's shared factor with every sensor's own calibration line taken out.

    A fixed gain and offset per sensor (reading = a + b x level) make the ratio of a
    sensor's mean to its simulated level differ from cell to cell, so the median
    ratio would vary over the runs with no change in time.  Factors and lines are
    fitted in turn: the factor is the median over sensors of mean / line(level), the
    lines fit mean / factor; the factors' geometric mean is 1 (the lines hold the scale).
    ``rounds`` 1: the plain median ratios (no lines, the scale kept).
    """
    mean = np.array([m for _, _, m, _, _ in rows])
    ref = np.array([f for _, _, _, f, _ in rows])
    ok = (ref > MIN_LEVEL) & np.isfinite(mean)
    a, b = np.zeros(mean.shape[1]), np.ones(mean.shape[1])
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


MIN_RUNS = 4           # runs a sensor needs for its own calibration line


def _level_of(rows) -> np.ndarray:
    """Each run's mean level (over sensors) in readings, for the fast variance's scale."""
    return np.array([np.mean(m[(f > MIN_LEVEL) & np.isfinite(m)]) for (_, _, m, f, _) in rows])


def _levels(recs, sensors) -> dict:
    acc: dict = {}
    for rec in recs:
        for r in replay.runs(rec):
            cell = (str(rec.condition[r[0]]), float(np.round(rec.heading_deg[r[0]], 1)))
            acc.setdefault(cell, []).append(rec.readings[r][:, sensors])
    return {cell: np.concatenate(v).mean(axis=0) for cell, v in acc.items()}


def shared_change(real: list, sim: list, sensors) -> dict | None:
    """The shared change over time in stationary recordings ``real`` against their
    replays ``sim`` (more episodes: copies), or None when there is none or no way to
    tell: {'p_value', 'ratio' (real over expected factor variance), 'runs': [(run
    indices into the recording, factor)] per real recording, 'sd' (of the factors)}.

    Expected is the simulator's factor variance plus what fast noise shared by the
    sensors adds to the real run means beyond the simulator's (a room's flicker moves a
    run's mean by its sd / sqrt(n): fast, not a change over time)."""
    sensors = list(sensors)
    if not real or not sim:
        return None
    reference = _levels(sim, sensors)
    rows_real = [_factors(rec, reference, sensors) for rec in real]
    rows_sim = [row for rec in sim for row in _factors(rec, reference, sensors)]
    flat = [row for rows in rows_real for row in rows]
    if len(flat) < 3 or len(rows_sim) < 3:
        return None
    # judged with the lines (no calibration can fake a change); the runs' factors are
    # the plain ratios: where a condition has one run, its lines absorb part of a change
    f_real, f_sim = _shared(flat), _shared(rows_sim)
    plain = _shared(flat, rounds=1)
    v_real, d_real = _about_mean(f_real)
    v_sim, d_sim = _about_mean(f_sim)
    if d_real < 2 or d_sim < 2 or v_sim <= 0:
        return None
    fast = [float(np.mean([w for *_, w in rows] / np.square(_level_of(rows))))
            for rows in (flat, rows_sim)]
    expected = v_sim + max(fast[0] - fast[1], 0.0)
    ratio = v_real / expected
    p = float(sps.f.sf(ratio, d_real, d_sim))
    excess = float(np.sqrt(max(v_real - expected, 0.0)))
    runs, k = [], 0
    for rows in rows_real:
        runs.append([(r, float(f)) for (r, *_), f in zip(rows, plain[k:k + len(rows)])])
        k += len(rows)
    return {'p_value': p, 'ratio': float(ratio), 'excess_sd': excess,
            'significant': p < ALPHA and excess >= MIN_CHANGE,
            'runs': runs, 'sd': float(np.std(plain))}


def _about_mean(factors) -> tuple[float, int]:
    v = np.log(factors)
    return float(np.var(v, ddof=1)), v.size - 1


def steady(rec, runs: list) -> np.ndarray:
    """The readings of ``rec`` with each run divided by its shared factor (the shared
    change removed), as floats."""
    out = rec.readings.astype(np.float64).copy()
    for r, f in runs:
        out[r] = out[r] / f
    return out


def of_target(target) -> dict | None:
    """``shared_change`` of a fitting target's stationary recordings (light-model base
    only: with the observed base the levels are the recording's own)."""
    if target.base == 'observed':
        return None
    real = target.of_kind('stationary')
    if not real:
        return None
    return shared_change(real, target.simulate(kinds=('stationary',)),
                         real[0].channels_used)


def steady_rows(rows: list, target, change: dict) -> list:
    """Level rows (key, real, sim, se, z) of a comparison with the real levels taken from
    the readings with the shared change removed."""
    real = target.of_kind('stationary')
    sums: dict = {}
    for rec, runs in zip(real, change['runs']):
        x = steady(rec, runs)
        for r, _ in runs:
            h = float(np.round(rec.heading_deg[r[0]], 1))
            cell = (str(rec.condition[r[0]]), None if not np.isfinite(h) else f'heading {h:g} deg')
            acc = sums.setdefault(cell, [0.0, 0])
            acc[0] = acc[0] + x[r].sum(axis=0)
            acc[1] += r.size
    out = []
    for k, r, s, se, z in rows:
        acc = sums.get((k.condition, k.part))
        if acc is not None:
            r = float(acc[0][k.sensors[0]] / acc[1])
            z = (r - s) / se
        out.append((k, r, s, se, z))
    return out
