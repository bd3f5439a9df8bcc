"""Closed-loop noise seen in the readings' changes, with no headings and no still steps.

A robot that logs only while it runs its task may never stand still (the project's
controller never commands power 0) and seldom knows its heading, so neither view of
``gap.closednoise`` exists.  What is left is each reading's next change: within an
episode it is the light's response to the last few turns plus the difference of two
noise draws.  Each sensor's change is regressed on the last four commands and on their
products with every reading (which side the lamp is on, how steep its light is): the
light's part is taken out, what is left is mostly noise (fitted on the whole recording,
per condition).  Per-episode sums of that *change residual* give ``loop_change_spread``
per sensor and level band (the variance halved, as for a difference of two draws) and,
on rows where the sensors read dark, ``loop_change_correlation`` per pair (noise shared
by sensors) and ``loop_change_autocorrelation`` at lag 1.  No reading is a regressor on
its own: it would carry the noise it shares and take it out of the residual.  See
docs/diagnosis.md.
"""
from __future__ import annotations

import numpy as np

from .blocks import Key

BANDS = (0.0, 175.0, 350.0)       # lower edges of the level bands (readings; 525 is dark)
LAGS = 4                          # commands u(t), ..., u(t - 3): a latency up to 3 steps
FAMILIES = frozenset(f'loop_change_{s}' for s in ('spread', 'correlation', 'autocorrelation'))
MIN_ROWS = 8                      # rows a statistic needs in the full data
# Correlation and autocorrelation on rows where the sensors read dark (little light, so
# the light's part the regression leaves is small beside the noise)
QUIET = 350.0
QUIET_PART = f'readings >= {QUIET:g}'


def episode_parts(rec, perturb_every: int, order: np.ndarray, ep: np.ndarray,
                  steps: np.ndarray, r: np.ndarray, power: np.ndarray, episodes: int,
                  by) -> dict:
    """{name: (episodes, ...) sums} of the change residuals; ``order`` puts the recording
    in episode then step order, as ``ep``, ``steps``, ``r`` and ``power`` are
    (``closednoise.episode_parts``); ``by(ep, values, episodes)`` sums rows by episode."""
    u = np.nan_to_num(rec.direction[order], nan=0.0) * power
    rows = _rows(ep, steps, perturb_every)
    e = np.zeros_like(r)
    use = np.zeros(len(r), bool)
    condition = rec.condition[order]
    for cond in np.unique(condition):
        at = rows[condition[rows] == cond]
        if at.size > 2 * (LAGS + 4):
            e[at] = _residuals(r, u, at)
            use[at] = True
    n = len(r)
    band = np.searchsorted(np.array(BANDS), r, side='right') - 1            # (N, 8)
    onehot = (band[:, None, :] == np.arange(len(BANDS))[None, :, None]) & use[:, None, None]
    quiet = (r >= QUIET) & use[:, None]
    eq = e * quiet
    both = quiet[:, :, None] & quiet[:, None, :]
    lagged = quiet & np.r_[False, (ep[1:] == ep[:-1]) & (steps[1:] == steps[:-1] + 1)][:, None]
    lagged[1:] &= quiet[:-1]
    lag = np.zeros_like(e)
    lag[1:] = e[1:] * e[:-1]

    def pairs(values):
        return by(ep, values.reshape(n, -1), episodes).reshape(episodes, 8, 8)
    return {'chg_band_n': by(ep, onehot.reshape(n, -1).astype(np.float64),
                             episodes).reshape(episodes, len(BANDS), 8),
            'chg_band_s2': 0.5 * by(ep, (onehot * (e * e)[:, None, :]).reshape(n, -1),
                                    episodes).reshape(episodes, len(BANDS), 8),
            'chg_q_n': pairs(both.astype(np.float64)),
            'chg_q_xy': 0.5 * pairs(eq[:, :, None] * eq[:, None, :]),
            'chg_q_xx': 0.5 * pairs((eq * eq)[:, :, None] * both),
            'chg_lag_n': by(ep, lagged.astype(np.float64), episodes),
            'chg_lag_s': 0.5 * by(ep, lag * lagged, episodes)}


def _rows(ep: np.ndarray, steps: np.ndarray, perturb_every: int) -> np.ndarray:
    """Rows t with t - LAGS + 1 .. t + 1 consecutive steps of one episode and t + 1 no
    knock (the knock, not the command, moves the heading there)."""
    t = np.arange(LAGS - 1, len(ep) - 1)
    ok = (ep[t + 1] == ep[t - LAGS + 1]) & (steps[t + 1] - steps[t - LAGS + 1] == LAGS) \
        & (steps[t + 1] % perturb_every != 0)
    return t[ok]


def _residuals(r: np.ndarray, u: np.ndarray, at: np.ndarray) -> np.ndarray:
    """(rows, 8) residuals of each sensor's next change on the commands u(t - j) and
    their products with every reading (which side the lamp is on, how steep its light)."""
    commands = np.stack([u[at - j] for j in range(LAGS)], axis=1)          # (n, LAGS)
    level = r[at] / 100.0
    x = np.concatenate([np.ones((at.size, 1)), commands,
                        (commands[:, :, None] * level[:, None, :]).reshape(at.size, -1)],
                       axis=1)
    dr = r[at + 1] - r[at]
    beta, *_ = np.linalg.lstsq(x, dr, rcond=None)
    return dr - x @ beta


def stats(b, sums: np.ndarray, s: int, condition: str) -> tuple[list, list]:
    """(keys, columns) of stratum ``s`` from the (R, S, D) sums (no keys where the
    recording has too few rows)."""
    keys, cols = [], []
    if 'chg_band_n' not in b.layout:
        return keys, cols
    band_n = b.part(sums, 'chg_band_n')[:, s]
    with np.errstate(divide='ignore', invalid='ignore'):
        spread = np.sqrt(b.part(sums, 'chg_band_s2')[:, s] / band_n)
        for j, (lo, hi) in enumerate(zip(BANDS, BANDS[1:] + (525.0,))):
            for k in range(8):
                if band_n[0, j, k] >= MIN_ROWS:
                    keys.append(Key('loop_change_spread', (k,), condition, f'level {lo:g}-{hi:g}'))
                    cols.append(spread[:, j, k])
        q_n, xx = b.part(sums, 'chg_q_n')[:, s], b.part(sums, 'chg_q_xx')[:, s]
        corr = b.part(sums, 'chg_q_xy')[:, s] / np.sqrt(xx * np.swapaxes(xx, 1, 2))
        for k in range(8):
            for m in range(k + 1, 8):
                if q_n[0, k, m] >= MIN_ROWS:
                    keys.append(Key('loop_change_correlation', (k, m), condition, QUIET_PART))
                    cols.append(corr[:, k, m])
        lag_n = b.part(sums, 'chg_lag_n')[:, s]
        var = np.diagonal(xx, axis1=-2, axis2=-1) / np.diagonal(q_n, axis1=-2, axis2=-1)
        lag = b.part(sums, 'chg_lag_s')[:, s] / lag_n / var
        for k in range(8):
            if lag_n[0, k] >= MIN_ROWS:
                keys.append(Key('loop_change_autocorrelation', (k,), condition, QUIET_PART))
                cols.append(lag[:, k])
    return keys, cols
