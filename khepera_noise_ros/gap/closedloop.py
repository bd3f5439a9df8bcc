"""Closed-loop statistics of the gap diagnosis: per-episode sums and the statistics built on
them (fitness factors by step after a perturbation, turn power and direction, the
regression of reading changes on the turn command, turn size where headings are
known).  Blocks are whole episodes; see ``gap.statistics`` for the resampling.
"""
from __future__ import annotations

import numpy as np

from ..recording import Recording
from . import closednoise, dropout, loopvalues, turnscatter
from .blocks import FACTORS, Blocks, Key, Stats, pack


def closed_loop_blocks(rec: Recording, perturb_every: int, loop_only: bool = False) -> Blocks:
    """Per-episode sums of closed-loop Khepera data (8 channels, s0..s5 in front); with
    ``loop_only`` (a diagnosis with no stationary recording), those of the value statistics
    (``gap.loopvalues``) and of the change residuals (``gap.loopchange``) too."""
    rec, dropped = dropout.repair_episodes(rec)      # a dropout counts once: on its own
    conditions = rec.conditions()
    heading_known = bool(np.isfinite(rec.heading_deg).all())
    rows: dict[str, list] = {n: [] for n in ('n', 'level', 'factor', 'phase_n', 'power',
                                             'right', 'xtx', 'xty', 'xty_sensor',
                                             'scatter_n', 'scatter_xx', 'scatter_xy',
                                             'scatter_yy', 'heading_band')}
    stratum = []
    for e in np.unique(rec.episode):
        idx = np.flatnonzero(rec.episode == e)
        idx = idx[np.argsort(rec.step[idx])]
        r = rec.readings[idx][:, :8].astype(np.float64)
        steps = rec.step[idx]
        u = rec.direction[idx] * rec.power[idx]
        phase = steps % perturb_every
        factors = _factors(r, rec.power[idx])
        onehot = (phase[:, None] == np.arange(perturb_every)[None, :]).astype(np.float64)
        rows['n'].append([idx.size])
        rows['level'].append(r.sum(axis=0))
        rows['factor'].append(factors.T @ onehot)
        rows['phase_n'].append(onehot.sum(axis=0))
        rows['power'].append(rec.power[idx] @ onehot)
        rows['right'].append([(rec.direction[idx] > 0).sum()])
        xtx, xty, xty_sensor, scatter = _turn_moments(r, u, steps, perturb_every)
        for name, value in scatter.items():
            rows[name].append(value)
        rows['xtx'].append(xtx)
        rows['xty'].append(xty)
        rows['xty_sensor'].append(xty_sensor)
        rows['heading_band'].append(
            turnscatter.heading_moments(rec.heading_deg[idx], u, steps, perturb_every)
            if heading_known else turnscatter.empty_heading())
        stratum.append(conditions.index(str(rec.condition[idx[0]])))
    parts = {n: np.asarray(v, np.float64) for n, v in rows.items()}
    parts.update(closednoise.episode_parts(rec, perturb_every, loop_only))   # noise structure
    parts.update(dropped)
    integer = False
    if loop_only:
        more, integer = loopvalues.episode_parts(rec, np.unique(rec.episode))
        parts.update(more)
    sums, layout = pack(parts, len(stratum))
    return Blocks('closed_loop', tuple(range(8)), conditions, np.asarray(stratum, np.int64),
                  sums, layout, {'perturb_every': perturb_every, 'heading': heading_known,
                                 'loop_only': loop_only, 'integer': integer})


def _factors(r: np.ndarray, power: np.ndarray) -> np.ndarray:
    """(T, 3) balance, intensity, turning per step, as in core.task.fitness_factors."""
    left, right = r[:, 0:3].mean(axis=1), r[:, 3:6].mean(axis=1)
    balance = 1.0 - np.abs(left - right) / 525.0
    intensity = 1.0 - (r[:, 2] + r[:, 3]) / (2 * 525.0)
    return np.stack([balance, intensity, (power != 0).astype(np.float64)], axis=1)


def _turn_moments(r: np.ndarray, u: np.ndarray, steps: np.ndarray, perturb_every: int):
    """Moments of the regression of the next change in readings on u(t) and u(t-1), and
    per power band those of its scatter (``gap.turnscatter``).

    Transitions into a perturbation step are left out: the knock, not the command,
    moves the heading there.
    """
    imbalance = r[:, 0:3].mean(axis=1) - r[:, 3:6].mean(axis=1)
    ok = turnscatter.regression_rows(steps, perturb_every)
    x = np.stack([u[ok], u[ok - 1], np.ones(ok.size)], axis=1)
    dy = imbalance[ok + 1] - imbalance[ok]
    dr = r[ok + 1] - r[ok]
    return x.T @ x, x.T @ dy, x.T @ dr, turnscatter.response_moments(r, u, ok)


def closed_loop_stats(b: Blocks, sums: np.ndarray) -> Stats:
    keys, cols = [], []
    n = b.part(sums, 'n')[..., 0]
    phases = b.extra['perturb_every']
    for s, c in enumerate(b.strata):
        level = b.part(sums, 'level')[:, s] / n[:, s, None]
        for k in range(8):
            keys.append(Key('closed_loop_level', (k,), c, None))
            cols.append(level[:, k])
        factor = b.part(sums, 'factor')[:, s]                    # (R, 3, P)
        count = b.part(sums, 'phase_n')[:, s]                    # (R, P)
        power = b.part(sums, 'power')[:, s] / count
        for p in range(phases):
            part = f'step {p} after perturbation'
            for f, name in enumerate(FACTORS):
                keys.append(Key(f'fitness_{name}', (0, 1, 2, 3, 4, 5), c, part))
                cols.append(factor[:, f, p] / count[:, p])
            keys.append(Key('turn_power', (), c, part))
            cols.append(power[:, p])
        keys.append(Key('turn_right_fraction', (), c, None))
        cols.append(b.part(sums, 'right')[:, s, 0] / n[:, s])
        xtx, xty = b.part(sums, 'xtx')[:, s], b.part(sums, 'xty')[:, s]
        beta = _solve(xtx, xty[..., None])[..., 0]               # (R, 3)
        for j, lag in enumerate(('lag 0', 'lag 1')):
            keys.append(Key('turn_response', (0, 1, 2, 3, 4, 5), c, lag))
            cols.append(beta[:, j])
        beta_s = _solve(xtx, b.part(sums, 'xty_sensor')[:, s])   # (R, 3, 8)
        for k in range(8):
            for j, lag in enumerate(('lag 0', 'lag 1')):
                keys.append(Key('sensor_turn_response', (k,), c, lag))
                cols.append(beta_s[:, j, k])
        if b.extra['heading']:          # every power 0..9 is in one band: sum the bands
            h = b.part(sums, 'heading_band')[:, s].sum(axis=1)  # (R, 4): n, u^2, u dh, dh^2
            keys.append(Key('turn_size', (), c, 'deg per unit of command'))
            cols.append(h[:, 2] / h[:, 1])
        for more in (closednoise.stats, turnscatter.scatter_stats, dropout.closed_loop_stats,
                     loopvalues.stats):
            more_keys, more_cols = more(b, sums, s, c)
            keys += more_keys
            cols += more_cols
    return Stats(keys, np.stack(cols, axis=1))


def _solve(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Batched least squares that tolerates singular moment matrices (NaN there)."""
    out = np.full(b.shape, np.nan)
    ok = np.abs(np.linalg.det(a)) > 1e-9
    if ok.any():
        out[ok] = np.linalg.solve(a[ok], b[ok])
    return out
