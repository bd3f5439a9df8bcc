"""Closed-loop statistics of the turn made per command, and of the readings settling after
a turn (per-episode sums beside ``closedloop``'s); the turns a recording measured, or
inferred through a heading sweep where the robot does not know its heading (the rules:
docs/identification.md)."""
from __future__ import annotations

from typing import Any, Callable, Sequence

import numpy as np

from ..effects.base import Array, Key
from ..recording import Recording
from . import bootstrap
from .closedloop import Part, imbalance, sum_by, wrap
from .protocol import calibrating, condition_world, consecutive, ordered, runs

COMMANDS = tuple(range(-9, 0)) + tuple(range(1, 10))     # signed powers, + to the right
MIN_TURNS = 4                    # rows a command's statistics need in the full data
BEFORE, AFTER, SETTLED = 2, 8, 4     # rests around a turn: before, after, the last settled
SAMPLES = 3                      # samples after a turn whose settling is compared
MIN_CHANGE = 100.0     # mean squared change a sensor's settling needs (10 readings a turn)
SIDES = ('bright', 'dark')
GRID = 0.5                 # degrees between the bearings an inferred turn is chosen from
BEARINGS = np.arange(-180.0, 180.0, GRID)
MIN_HEADINGS = 8           # a sweep's headings needed to infer a heading from readings
MARGIN = 10.0              # degrees searched beyond twice the commanded turn


def knocks(rec: Recording, steps: np.ndarray, every: int) -> np.ndarray:
    """The rows a knock moves: none when the recording's task has no knock."""
    task = rec.manifest.get('task') or {}
    out: np.ndarray = (steps % int(every) == 0) & (float(task.get('perturbation_deg', 1.0)) != 0)
    return out


def loop_sums(rec: Recording, x: Array, order: np.ndarray, ep: np.ndarray, episodes: int,
              every: int) -> dict[str, Array]:
    """Per-episode sums: per signed command the change of the readings' imbalance and,
    where headings are known, the turn made; the readings after a lone turn."""
    steps = rec.step[order]
    u = np.nan_to_num(rec.direction[order] * rec.power[order])
    r = x[order][:, :8].astype(np.float64)
    knock = knocks(rec, steps, every)
    ok = np.flatnonzero(_shown(consecutive(ep, steps), knock, u))
    onehot = (np.rint(u[ok])[:, None] == np.array(COMMANDS)[None, :]).astype(np.float64)
    front = imbalance(r)
    changes = {'tc_imb': front[ok + 1] - front[ok]}
    heading = rec.heading_deg[order]
    if np.isfinite(heading).all():
        changes['tc_turn'] = wrap(heading[ok + 1] - heading[ok])
    out = {}
    for name, v in changes.items():
        moments = np.stack([np.ones_like(v), v, v * v], axis=1)
        out[name] = sum_by(ep[ok], onehot[:, :, None] * moments[:, None, :], episodes)
    return {**out, **_settling(r, u, ep, steps, knock, episodes)}


def _shown(pair: np.ndarray, knock: np.ndarray, u: Array) -> np.ndarray:
    """Rows whose command shows in the next: a turn commanded, the next row its episode's
    next step and no knock there (``pair``: ``protocol.consecutive``)."""
    out: np.ndarray = np.r_[pair[1:], False] & ~np.r_[knock[1:], False] & (u != 0)
    return out


def _settling(r: Array, u: Array, ep: np.ndarray, steps: np.ndarray, knock: np.ndarray,
              episodes: int) -> dict[str, Array]:
    """Per side of each sensor's change over a lone turn, the products (reading after -
    settled)(before - settled) and (before - settled)^2."""
    dd = np.zeros((episodes, 2, SAMPLES, r.shape[1]))
    d2, n = np.zeros((episodes, 2, r.shape[1])), np.zeros((episodes, 2, r.shape[1]))
    t = lone(u, ep, steps, knock)
    old = r[t[:, None] + np.arange(-BEFORE, 1)[None, :]].mean(axis=1)
    new = r[t[:, None] + np.arange(AFTER - SETTLED + 1, AFTER + 1)[None, :]].mean(axis=1)
    change = old - new
    side = (change < 0).astype(np.int64)             # 0: towards bright, 1: dark
    sensor = np.broadcast_to(np.arange(r.shape[1]), change.shape)
    e = np.broadcast_to(ep[t][:, None], change.shape)
    np.add.at(d2, (e, side, sensor), change ** 2)
    np.add.at(n, (e, side, sensor), 1.0)
    for j in range(SAMPLES):
        np.add.at(dd[:, :, j], (e, side, sensor), (r[t + 1 + j] - new) * change)
    return {'tc_dd': dd, 'tc_d2': d2, 'tc_n': n}


def lone(u: Array, ep: np.ndarray, steps: np.ndarray, knock: np.ndarray) -> np.ndarray:
    """Rows (in episode and step order) of lone turns: rests of power 0 and no knock
    ``BEFORE`` rows before and ``AFTER`` after, in one run of steps."""
    span = np.arange(-BEFORE, AFTER + 1)
    t = np.flatnonzero(u != 0)
    t = t[(t >= BEFORE) & (t + AFTER < len(u))]
    rows = t[:, None] + span[None, :]
    same = (ep[rows] == ep[t][:, None]).all(axis=1) & \
        (steps[rows] - steps[t][:, None] == span[None, :]).all(axis=1)
    rest = (u[rows][:, span != 0] == 0).all(axis=1)
    calm = ~knock[rows[:, 1:]].any(axis=1)
    out: np.ndarray = t[same & rest & calm]
    return out


def stats(b: bootstrap.Blocks, s: Array, i: int, c: str) -> tuple[list[Key], list[Array]]:
    """Stratum ``i``'s turn statistics: ``turn_imbalance`` and, with headings,
    ``turn_by_command`` and its scatter per signed command; ``turn_step_response``."""
    out: list[tuple[Key, Array]] = []
    with np.errstate(invalid='ignore', divide='ignore'):
        for name, family in (('tc_imb', 'turn_imbalance'), ('tc_turn', 'turn_by_command')):
            if not b.has(name):
                continue
            m = b.part(s, name)[:, i]                     # (R, commands, 3)
            mean = m[..., 1] / m[..., 0]
            sd = np.sqrt(np.clip(m[..., 2] / m[..., 0] - mean ** 2, 0.0, None))
            for j, command in enumerate(COMMANDS):
                if m[0, j, 0] < MIN_TURNS:
                    continue
                part = f'{"right" if command > 0 else "left"} {abs(command)}'
                out.append((Key(family, (), c, part), mean[:, j]))
                if family == 'turn_by_command':
                    out.append((Key('turn_by_command_scatter', (), c, part), sd[:, j]))
        if b.has('tc_dd'):
            dd, d2 = b.part(s, 'tc_dd')[:, i], b.part(s, 'tc_d2')[:, i]
            n = b.part(s, 'tc_n')[0, i]
            out += [(Key('turn_step_response', (k,), c, f'sample {j} towards {label}'),
                     dd[:, side, j, k] / d2[:, side, k])
                    for side, label in enumerate(SIDES) for k in range(d2.shape[-1])
                    if n[side, k] >= MIN_TURNS and d2[0, side, k] >= MIN_CHANGE * n[side, k]
                    for j in range(SAMPLES)]
    return [k for k, _ in out], [v for _, v in out]


def with_stats(more: Part) -> Part:
    """``more``'s statistics of a stratum followed by the turn statistics."""
    def both(b: bootstrap.Blocks, s: Array, i: int, c: str) -> tuple[list[Key], list[Array]]:
        k1, c1 = more(b, s, i, c)
        k2, c2 = stats(b, s, i, c)
        return k1 + k2, c1 + c2
    return both


def sums(rec: Recording, x: Array, every: int, more: Callable[..., dict[str, Any]]
         ) -> Callable[[np.ndarray, np.ndarray, int], dict[str, Array]]:
    """``more``'s per-episode sums followed by the turn sums of a turn calibration; a
    controller's episodes keep their statistics (its turns are few per command and tied
    to what it saw)."""
    if not calibrating(rec):
        return more
    return lambda order, ep, m: {**more(order, ep, m), **loop_sums(rec, x, order, ep, m, every)}


def measured(loops: Sequence[Recording], sweeps: Sequence[Recording], config: Any) -> Array:
    """(n, 2) commanded and made turns, degrees (+ to the right): from consecutive
    headings where they are known, else (lone turns of a calibration) from the settled
    readings after the turn through a sweep of the same condition."""
    out = [np.zeros((0, 2))]
    for rec in loops:
        _, ep, order, steps, pair = ordered(rec)
        u = np.nan_to_num(rec.direction[order] * rec.power[order])
        h = rec.heading_deg[order]
        per = np.array([condition_world(rec, str(c), config.world).deg_per_power
                        for c in rec.condition[order]])
        knock = knocks(rec, steps, config.task.perturb_every)
        t = np.flatnonzero(_shown(pair, knock, u) & np.isfinite(h)
                           & np.isfinite(np.r_[h[1:], np.nan]))
        out.append(np.stack([u[t] * per[t], wrap(h[t + 1] - h[t])], axis=1))
        if calibrating(rec):
            out.append(_inferred(rec, sweeps, config, u * per, ep, steps, knock, h, order))
    return np.concatenate(out)


def _inferred(rec: Recording, sweeps: Sequence[Recording], config: Any, c: Array,
              ep: np.ndarray, steps: np.ndarray, knock: np.ndarray, h: Array,
              order: np.ndarray) -> Array:
    """(n, 2) the calibration's lone turns whose end heading is not known, each end
    inferred from the settled readings through a sweep (near the placement, the episode's
    first heading, for the start; within twice the command of it for the end)."""
    alone = lone(c, ep, steps, knock)
    alone = alone[~np.isfinite(h[alone + AFTER])]
    x = rec.readings[order][:, :8].astype(np.float64)
    placed = h[np.r_[0, np.flatnonzero(np.diff(ep)) + 1]][ep[alone]]   # episodes 0 .. m - 1
    out = []
    for i, place in zip(alone, placed):
        world = condition_world(rec, str(rec.condition[order][i]), config.world)
        reference = _sweep(sweeps, world)
        if reference is None or not np.isfinite(place):
            continue
        before = x[i - BEFORE:i + 1].mean(axis=0)
        after = x[i + AFTER - SETTLED + 1:i + AFTER + 1].mean(axis=0)
        start = h[i] if np.isfinite(h[i]) else \
            place + _infer(reference, before, place, -60.0, 60.0)
        made = _infer(reference, after, start, min(0.0, 2 * c[i]) - MARGIN,
                      max(0.0, 2 * c[i]) + MARGIN)
        out.append((c[i], made))
    return np.array(out, np.float64).reshape(-1, 2)


def _sweep(sweeps: Sequence[Recording], world: Any) -> tuple[Array, Array] | None:
    """(levels (``BEARINGS``, 8), their sd per sensor) interpolated from the stationary
    runs in ``world``'s condition, None with fewer than ``MIN_HEADINGS``."""
    cells: dict[float, list[Array]] = {}
    spread = []
    for rec in sweeps:
        for r in runs(rec):
            w = condition_world(rec, str(rec.condition[r[0]]), world)
            if w != world or not np.isfinite(rec.heading_deg[r[0]]) or r.size < 2:
                continue
            x = rec.readings[r][:, :8].astype(np.float64)
            cells.setdefault(round(float(wrap(rec.heading_deg[r[0]])), 1), []).append(x)
            spread.append(x.var(axis=0, ddof=1))
    if len(cells) < MIN_HEADINGS:
        return None
    known = np.array(sorted(cells))
    means = np.array([np.concatenate(cells[b]).mean(axis=0) for b in known])
    table = np.stack([np.interp(BEARINGS, known, means[:, k], period=360.0) for k in range(8)],
                     axis=1)
    return table, np.sqrt(np.mean(spread, axis=0)) + 1.0


def _infer(reference: tuple[Array, Array], settled: Array, start: float, lo: float,
           hi: float) -> float:
    """The offset from ``start`` (within ``lo`` .. ``hi`` degrees) of the bearing whose sweep
    levels lie nearest the settled readings."""
    table, sd = reference
    offsets = np.arange(lo, hi + GRID, GRID)
    at = np.rint((wrap(start + offsets) + 180.0) / GRID).astype(int) % BEARINGS.size
    cost = (((table[at] - settled) / sd) ** 2).sum(axis=1)
    return float(offsets[int(np.argmin(cost))])
