"""Closed-loop statistics of a zero-mean random turn error: the scatter of the turn.

A slip that is as often left as right leaves means and regression slopes alone;
it shows as scatter.  With recorded headings: the heading change's scatter about
the fitted turn per unit of command.  Without: the scatter of the readings'
response to a turn about the regression of ``gap.closedloop``.  Both by band of
commanded power (power 0 shows a creep, the others a slip that grows with the
turn).  Sums are per episode, like every closed-loop sum.
"""
from __future__ import annotations

import numpy as np

from .blocks import Blocks, Key

BANDS = ((0, 0), (1, 5), (6, 9))       # commanded power, both ends included


def band_label(band) -> str:
    lo, hi = band
    return f'power {lo}' if lo == hi else f'power {lo}-{hi}'


def _band_of(power: np.ndarray) -> np.ndarray:
    """(N, len(BANDS)) one-hot band of each |command|."""
    p = np.abs(np.rint(power))
    return np.stack([(p >= lo) & (p <= hi) for lo, hi in BANDS], axis=1).astype(np.float64)


def regression_rows(steps: np.ndarray, perturb_every: int) -> np.ndarray:
    """Rows j of the turn regression: j - 1, j, j + 1 consecutive and j + 1 no
    perturbation step (the knock, not the command, moves the heading there)."""
    j = np.arange(1, len(steps) - 1)
    keep = (steps[j + 1] == steps[j] + 1) & (steps[j - 1] == steps[j] - 1) \
        & (steps[j + 1] % perturb_every != 0)
    return j[keep]


def response_moments(r: np.ndarray, u: np.ndarray, ok: np.ndarray) -> dict:
    """Per band: count, x'x, x'dr, dr'dr (summed over sensors) of the regression of every
    reading's next change dr on x = (u(t), u(t-1), 1, r(t), u(t) r(t) / 100) at the rows
    ``ok``.  The readings and their product with the command take out most of the
    change's dependence on where the lamp is; what is left is noise and the turn's own
    scatter."""
    x = design(r, u, ok)
    dr = r[ok + 1] - r[ok]
    w = _band_of(u[ok])
    return {'scatter_n': w.sum(axis=0),
            'scatter_xx': np.einsum('nb,ni,nj->bij', w, x, x),
            'scatter_xy': np.einsum('nb,ni,nk->bik', w, x, dr),
            'scatter_yy': w.T @ (dr * dr).sum(axis=1)}


def design(r: np.ndarray, u: np.ndarray, ok: np.ndarray) -> np.ndarray:
    ut = u[ok, None]
    return np.concatenate([ut, u[ok - 1, None], np.ones_like(ut), r[ok], ut * r[ok] / 100.0],
                          axis=1)


def heading_moments(heading: np.ndarray, u: np.ndarray, steps: np.ndarray,
                    perturb_every: int) -> np.ndarray:
    """(len(BANDS), 4) per band: count, sum u^2, sum u dh, sum dh^2 over consecutive
    unperturbed steps."""
    ok = np.flatnonzero(np.diff(steps) == 1)
    ok = ok[(steps[ok + 1] % perturb_every) != 0]
    dh = (heading[ok + 1] - heading[ok] + 180.0) % 360.0 - 180.0
    uu = u[ok]
    w = _band_of(uu)
    return w.T @ np.stack([np.ones(ok.size), uu * uu, uu * dh, dh * dh], axis=1)


def empty_heading() -> np.ndarray:
    return np.zeros((len(BANDS), 4))


def scatter_stats(b: Blocks, sums: np.ndarray, s: int, condition: str) -> tuple[list, list]:
    """Keys and (R,) columns of stratum ``s``: ``turn_scatter`` (the readings' change per
    band about the pooled regression, rms over sensors) and, with headings,
    ``turn_size_scatter`` (degrees per step about the pooled turn per unit of command)."""
    keys, cols = [], []
    n = b.part(sums, 'scatter_n')[:, s]                         # (R, B)
    xx = b.part(sums, 'scatter_xx')[:, s]                       # (R, B, 3, 3)
    xy = b.part(sums, 'scatter_xy')[:, s]                       # (R, B, P, C)
    yy = b.part(sums, 'scatter_yy')[:, s]                       # (R, B)
    beta = _solve(xx.sum(axis=1), xy.sum(axis=1))               # (R, P, C)
    rss = yy - 2 * np.einsum('rbik,rik->rb', xy, beta) \
        + np.einsum('rik,rbij,rjk->rb', beta, xx, beta)
    for j, band in enumerate(BANDS):
        keys.append(Key('turn_scatter', tuple(range(8)), condition, band_label(band)))
        cols.append(_rms(rss[:, j], n[:, j] * 8))
    if b.extra.get('heading'):
        h = b.part(sums, 'heading_band')[:, s]                  # (R, B, 4)
        total = h.sum(axis=1)
        k = total[:, 2] / total[:, 1]
        for j, band in enumerate(BANDS):
            rss_h = h[:, j, 3] - 2 * k * h[:, j, 2] + k * k * h[:, j, 1]
            keys.append(Key('turn_size_scatter', (), condition, band_label(band)))
            cols.append(_rms(rss_h, h[:, j, 0]))
    return keys, cols


def _rms(rss: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Root mean square residual; NaN where a band has fewer than 3 rows."""
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(n >= 3, np.sqrt(np.clip(rss, 0.0, None) / n), np.nan)


def _solve(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Batched least squares by pseudo-inverse (a band or a resample can leave the
    moment matrix singular: a command that never varies)."""
    with np.errstate(invalid='ignore'):
        return np.linalg.pinv(a, rcond=1e-10, hermitian=True) @ b
