"""The turn-calibration protocol: its replay (the recorded commands from the recorded
placements), and the turns it measured, or inferred from the readings through a heading
sweep where the robot does not know its heading (docs/identification.md)."""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from ..effects.base import Array
from ..effects.simulate import EffectEpisodes
from ..recording import Recording
from . import closedloop, turns
from .protocol import condition_world, runs

GRID = 0.5                 # degrees between the bearings an inferred turn is chosen from
MIN_HEADINGS = 8           # a sweep's headings needed to infer a heading from readings
MARGIN = 10.0              # degrees searched beyond twice the commanded turn


def calibrating(rec: Recording) -> bool:
    """Is ``rec`` a turn calibration (commands of the protocol, not of a genome)?"""
    return rec.manifest.get('calibration') == 'turns'


def run(env: EffectEpisodes, rec: Recording, episodes: np.ndarray, seeds: np.ndarray,
        ids: np.ndarray, label: str) -> dict[str, np.ndarray]:
    """The recorded commands of ``episodes`` (tiled over copies as ``seeds``) from each
    episode's recorded first heading, in ``env``."""
    steps = env.task.steps
    copies = seeds.size // episodes.size
    start = np.zeros(episodes.size)
    command = np.zeros((2, steps, episodes.size))
    command[0] = 1.0
    for i, e in enumerate(episodes):
        at = rec.episode == e
        first = np.argmin(np.where(at, rec.step, np.iinfo(np.int64).max))
        start[i] = np.nan_to_num(rec.heading_deg[first])
        s = rec.step[at]
        command[0, s, i] = np.nan_to_num(rec.direction[at], nan=1.0)
        command[1, s, i] = np.nan_to_num(rec.power[at])
    command = np.tile(command, (1, 1, copies))
    readings: Array | None = env.reset(seeds, bearing_deg=np.tile(start, copies))
    rows = []
    t = 0
    while readings is not None:
        d, p = command[0, t].astype(np.int64), command[1, t].astype(np.int64)
        rows.append((env.bearing_deg.copy(), readings.copy(), d, p))
        readings = env.step(d, p)
        t += 1
    n, t = seeds.size, len(rows)
    return {'episode': np.repeat(ids, t), 'step': np.tile(np.arange(t), n),
            'heading_deg': np.stack([r[0] for r in rows], axis=1).ravel(),
            'condition': np.full(n * t, label),
            'readings': np.stack([r[1] for r in rows], axis=1).reshape(n * t, -1)
            .astype(np.float64),
            'direction': np.stack([r[2] for r in rows], axis=1).ravel().astype(np.float64),
            'power': np.stack([r[3] for r in rows], axis=1).ravel().astype(np.float64)}


def measured(loops: Sequence[Recording], sweeps: Sequence[Recording],
             config: Any) -> Array:
    """(n, 2) commanded and made turns, degrees (+ to the right): from consecutive
    headings where they are known, else (lone turns of a calibration) from the settled
    readings after the turn through a sweep of the same condition."""
    out = [np.zeros((0, 2))]
    for rec in loops:
        _, ep, order, steps, pair = closedloop.ordered(rec)
        u = np.nan_to_num(rec.direction[order] * rec.power[order])
        h = rec.heading_deg[order]
        labels = rec.condition[order]
        per = np.array([condition_world(rec, str(c), config.world).deg_per_power
                        for c in labels])
        every = turns.knock_every(rec, config.task.perturb_every)
        knock = np.zeros(len(u), bool) if every is None else steps % every == 0
        nxt = np.r_[pair[1:], False] & ~np.r_[knock[1:], False]
        t = np.flatnonzero(nxt & (u != 0) & np.isfinite(h) & np.isfinite(np.r_[h[1:], np.nan]))
        out.append(np.stack([u[t] * per[t], _wrap(h[t + 1] - h[t])], axis=1))
        if calibrating(rec):
            out.append(_inferred(rec, sweeps, config, u * per, ep, steps, knock, h, order))
    return np.concatenate(out)


def _inferred(rec: Recording, sweeps: Sequence[Recording], config: Any, c: Array,
              ep: np.ndarray, steps: np.ndarray, knock: np.ndarray, h: Array,
              order: np.ndarray) -> Array:
    """(n, 2) the calibration's lone turns whose end heading is not known, each end
    inferred from the settled readings through a sweep (near the placement, the episode's
    first heading, for the start; within twice the command of it for the end)."""
    lone = turns.lone(c, ep, steps, knock)
    lone = lone[~np.isfinite(h[lone + turns.AFTER])]
    x = rec.readings[order][:, :8].astype(np.float64)
    first = np.r_[0, np.flatnonzero(np.diff(ep)) + 1]
    placed = h[first][np.searchsorted(first, lone, side='right') - 1]
    out = []
    for i, place in zip(lone, placed):
        reference = _sweep(sweeps, condition_world(rec, str(rec.condition[order][i]),
                                                   config.world))
        if reference is None or not np.isfinite(place):
            continue
        before = x[i - turns.BEFORE:i + 1].mean(axis=0)
        after = x[i + turns.AFTER - turns.SETTLED + 1:i + turns.AFTER + 1].mean(axis=0)
        start = h[i] if np.isfinite(h[i]) else place + _infer(reference, before, place,
                                                              -60.0, 60.0)
        made = _infer(reference, after, start, min(0.0, 2 * c[i]) - MARGIN,
                      max(0.0, 2 * c[i]) + MARGIN)
        out.append((c[i], made))
    return np.array(out, np.float64).reshape(-1, 2)


def _wrap(deg: Array) -> Array:
    out: Array = (deg + 180.0) % 360.0 - 180.0
    return out


def _sweep(sweeps: Sequence[Recording], world: Any) -> tuple[Array, Array] | None:
    """(levels (bearings on the grid, 8), their sd per sensor) interpolated from the
    stationary runs in ``world``'s condition, None with fewer than ``MIN_HEADINGS``."""
    cells: dict[float, list[Array]] = {}
    spread = []
    for rec in sweeps:
        for r in runs(rec):
            w = condition_world(rec, str(rec.condition[r[0]]), world)
            if w != world or not np.isfinite(rec.heading_deg[r[0]]) or r.size < 2:
                continue
            x = rec.readings[r][:, :8].astype(np.float64)
            cells.setdefault(round(float(_wrap(rec.heading_deg[r[0]])), 1), []).append(x)
            spread.append(x.var(axis=0, ddof=1))
    if len(cells) < MIN_HEADINGS:
        return None
    known = np.array(sorted(cells))
    means = np.array([np.concatenate(cells[b]).mean(axis=0) for b in known])
    grid = np.arange(-180.0, 180.0, GRID)
    table = np.stack([np.interp(grid, known, means[:, k], period=360.0) for k in range(8)],
                     axis=1)
    return table, np.sqrt(np.mean(spread, axis=0)) + 1.0


def _infer(reference: tuple[Array, Array], settled: Array, start: float, lo: float,
           hi: float) -> float:
    """The offset from ``start`` (within ``lo`` .. ``hi`` degrees) of the bearing whose sweep
    levels lie nearest the settled readings."""
    table, sd = reference
    grid = np.arange(-180.0, 180.0, GRID)
    offsets = np.arange(lo, hi + GRID, GRID)
    at = np.rint((_wrap(start + offsets) + 180.0) / GRID).astype(int) % grid.size
    cost = (((table[at] - settled) / sd) ** 2).sum(axis=1)
    return float(offsets[int(np.argmin(cost))])
