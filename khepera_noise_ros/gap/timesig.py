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
    """[(run samples, cell, shared factor)] of a stationary recording against the
    simulated cell levels ``reference`` {(condition, heading): level per sensor}."""
    out = []
    for r in replay.runs(rec):
        cell = (str(rec.condition[r[0]]), float(np.round(rec.heading_deg[r[0]], 1)))
        ref = reference.get(cell)
        if ref is None or r.size < 2:
            continue
        mean = rec.readings[r][:, sensors].mean(axis=0)
        ok = (ref > MIN_LEVEL) & np.isfinite(mean)
        if ok.sum() >= MIN_SENSORS:
            out.append((r, cell, float(np.median(mean[ok] / ref[ok]))))
    return out


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
    tell: {'p_value', 'ratio' (real over simulated factor variance), 'runs': [(run
    indices into the recording, factor)] per real recording, 'sd' (of the factors)}."""
    sensors = list(sensors)
    if not real or not sim:
        return None
    reference = _levels(sim, sensors)
    rows_real = [_factors(rec, reference, sensors) for rec in real]
    rows_sim = [row for rec in sim for row in _factors(rec, reference, sensors)]
    flat = [row for rows in rows_real for row in rows]
    if len(flat) < 3 or len(rows_sim) < 3:
        return None
    v_real, d_real = _about_mean(flat)
    v_sim, d_sim = _about_mean(rows_sim)
    if d_real < 2 or d_sim < 2 or v_sim <= 0:
        return None
    ratio = v_real / v_sim
    p = float(sps.f.sf(ratio, d_real, d_sim))
    excess = float(np.sqrt(max(v_real - v_sim, 0.0)))
    return {'p_value': p, 'ratio': float(ratio), 'excess_sd': excess,
            'significant': p < ALPHA and excess >= MIN_CHANGE,
            'runs': [[(r, f) for r, _, f in rows] for rows in rows_real],
            'sd': float(np.std([f for *_, f in flat]))}


def _about_mean(rows) -> tuple[float, int]:
    v = np.log([f for *_, f in rows])
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
    real = [r for r, k in zip(target.recordings, target.kinds) if k == 'stationary']
    if not real:
        return None
    return shared_change(real, target.simulate(kinds=('stationary',)),
                         real[0].channels_used)


def steady_rows(rows: list, target, change: dict) -> list:
    """Level rows (key, real, sim, se, z) of a comparison with the real levels taken from
    the readings with the shared change removed."""
    real = [r for r, k in zip(target.recordings, target.kinds) if k == 'stationary']
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
