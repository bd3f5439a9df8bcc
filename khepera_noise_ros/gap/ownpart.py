"""Each sensor's own part of a stationary run's residuals, where a wander of its own shows.

A fast noise shared by all sensors (a room's flicker) can be many times a sensor's
own noise, and it is white: it leaves the residuals' autocorrelation near zero, so a
slow wander of one sensor's gain hides under it.  Within each run the part a sensor
shares with the others (its least-squares regression on the mean residual of the
other sensors) is taken out; the first ``SKIP`` samples of a run (the step response
after a change of heading) are left out.  The lagged products and squares of what is
left become the ``own_autocorrelation`` statistics, on real and simulated runs alike
(``gap.ownwander`` locates the wandering sensors from own parts made the same way,
run by run).
"""
from __future__ import annotations

import numpy as np

SKIP = 3               # first samples of a run left out (``gap.ownwander`` skips the same)
MIN_CHANNELS = 3       # with fewer, the others' mean is one sensor: no shared part to take out


def residuals(y: np.ndarray, lay: dict) -> np.ndarray:
    """(samples, C) own parts (single precision) of the run residuals ``y`` (sample
    order), zero at the first ``SKIP`` samples of every run; ``lay`` the layout of
    ``statistics._layout`` (its runs, and whether they are in sample order)."""
    order, starts, sizes = lay['run_at']
    c = y.shape[1]
    if c < MIN_CHANNELS or not sizes.size:
        return np.zeros(y.shape, np.float32)
    if 'own_kept' not in lay:        # the same for every replay of the protocol
        position = np.arange(int(sizes.sum())) - np.repeat(starts, sizes)
        lay['own_kept'] = (position >= SKIP).astype(np.float32)[:, None]
    ordered = lay['runs_sorted']
    yr = (y if ordered else y[order]).astype(np.float32)
    yr *= lay['own_kept']
    others = yr.sum(axis=1, keepdims=True) - yr
    others *= np.float32(1.0 / (c - 1))
    cross = np.add.reduceat(yr * others, starts, axis=0)
    square = np.add.reduceat(others * others, starts, axis=0)
    beta = np.divide(cross, square, out=np.zeros_like(cross), where=square > 0)
    others *= np.repeat(beta, sizes, axis=0)
    yr -= others
    if ordered:
        return yr
    out = np.empty_like(yr)
    out[order] = yr
    return out


def autocorrelation(lag_sums: np.ndarray, squares: np.ndarray) -> np.ndarray:
    """(R, L, C) own autocorrelation from summed lagged products (R, L, C) and squares
    (R, C); NaN where a sensor has no own part."""
    return lag_sums / squares[:, None, :]
