"""Value statistics of closed-loop recordings: the value lattice of every sensor's readings
(``loop_granularity``), per condition.

A lattice shows in any reading stream, whatever the heading, so it needs no stationary
robot.  Per episode (the closed loop's blocks) the sums are weighted counts of the
values inside a sensor's range and of those on its most common residue modulo each
step of ``MODULI`` (each value seen counts once); the statistics are ratios of the
resampled sums.  ``closedloop`` adds them only when a diagnosis has no stationary
recording (``loop_only``): beside one they would repeat its granularity.  (A pile-up
statistic was tried and left out: docs/diagnosis.md.)
"""
from __future__ import annotations

import numpy as np

from .blocks import MODULI, Key

FAMILIES = frozenset({'loop_granularity'})
MIN_VALUES = 12     # values inside its range a sensor needs for its lattice statistics


def episode_parts(rec, episodes: np.ndarray) -> tuple[dict, bool]:
    """({name: (episodes, ...) sums}, whether the readings are integers), episodes in
    the order of ``episodes`` (``np.unique`` of ``rec.episode``)."""
    r = rec.readings[:, :8].astype(np.float64)
    ep = np.searchsorted(episodes, rec.episode)
    order = np.argsort(ep, kind='stable')
    starts = np.searchsorted(ep[order], np.arange(episodes.size))

    def per_episode(values: np.ndarray) -> np.ndarray:
        return np.add.reduceat(values[order], starts, axis=0).astype(np.float64)
    parts = {}
    integer = bool(np.isfinite(r).all() and np.all(r == np.round(r)))
    if integer:
        weight, on = on_lattice(r)
        parts['lv_weight'] = per_episode(weight)
        parts['lv_residue'] = per_episode(on * weight[..., None])
    return parts, integer


def on_lattice(r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((N, C) the weight of each reading: 1 over the number of readings of the sensor at
    its value, 0 at the sensor's least and greatest value; (N, C, Q) 1 where a reading
    lies on the sensor's most common residue modulo each step, counted so).  Each value
    seen counts once, however often: a reading held at one value (the light model's
    brightest, a clip, the robot parked) does not make a lattice."""
    low, high = r.min(axis=0), r.max(axis=0)
    weight = np.zeros(r.shape)
    on = np.zeros(r.shape + (len(MODULI),))
    for k in range(r.shape[1]):
        values, index, counts = np.unique(r[:, k], return_inverse=True, return_counts=True)
        inner = (values > low[k]) & (values < high[k])
        weight[:, k] = np.where(inner, 1.0 / counts, 0.0)[index.ravel()]
        for j, q in enumerate(MODULI):
            residue = np.mod(values, q).astype(np.int64)
            modal = np.bincount(residue[inner], minlength=q).argmax()
            on[:, k, j] = (residue == modal)[index.ravel()]
    return weight, on


def stats(b, sums: np.ndarray, s: int, condition: str) -> tuple[list, list]:
    """(keys, columns) of stratum ``s`` (one condition) from the (R, S, D) sums; none
    unless the blocks carry them (``loop_only``)."""
    if not b.extra.get('loop_only'):
        return [], []
    keys, cols = [], []
    if b.extra.get('integer'):
        weight = b.part(sums, 'lv_weight')[:, s]                          # (R, 8)
        share = b.part(sums, 'lv_residue')[:, s] / weight[..., None]     # (R, 8, Q)
        for k in range(8):
            if weight[0, k] < MIN_VALUES:
                continue
            for j, q in enumerate(MODULI):
                keys.append(Key('loop_granularity', (k,), condition, f'step {q}'))
                cols.append(share[:, k, j])
    return keys, cols
