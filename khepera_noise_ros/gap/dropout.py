"""Isolated readings stuck at a sensor's lowest or highest value, far from their neighbours.

A dropout is a lost sample: the converter reads zero, or the top of its scale, for
one step, whatever the light.  Its fingerprint is a reading at the sensor's extreme
value (its lowest or highest over the recording: 0 or the scale's top once it has
dropouts, whatever the scale) lying far from the *local* level, the median of the two
readings before and the two after it in the same run: by ``AWAY`` readings and by
``SPREADS`` robust sds of the run's readings about that local level.  The local level
follows a slow drift and a closed-loop robot's turns; the robust sd grows with a
spread law or a group's shared noise beside it; a gain moves a run's level, not its
single readings.  A floor or ceiling clips whole stretches of a run, so its readings
at the extreme lie next to others at it (not far), and are not dropouts.

``hits`` marks them per sample; the gap statistics compare their share per sensor and
end (family ``dropout`` for stationary runs, ``closed_loop_dropout`` for closed-loop
episodes) and see the other statistics on readings with them repaired (``repair``);
``gap.limits`` counts them to fit ``saturation_quantization``'s dropout.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from .blocks import Key

ENDS = ('to the lowest reading', 'to the highest reading')
AWAY = 10.0          # readings: a dropout lies at least this far from the local level
SPREADS = 6.0        # ... and this many robust sds of the run (a normal tail: ~2e-9)
NEAR = (-2, -1, 1, 2)    # the neighbours whose median is the local level
STEADY = 2.0         # ... and this many times the largest change among the neighbours
FAMILIES = frozenset({'dropout', 'closed_loop_dropout'})


def hits(x: np.ndarray, runs: list) -> np.ndarray:
    """(N, C, 2) float32: 1 where sample t of channel k is an isolated reading at the
    channel's lowest (end 0) or highest (end 1) finite value; ``runs``: sample indices
    of each run in step order (runs shorter than 3 samples have no neighbours)."""
    return repair(x, runs)[1]


def repair(x: np.ndarray, runs: list) -> tuple[np.ndarray, np.ndarray]:
    """(``x`` with each dropout read as a neighbour's level (the lower of the middle two
    of its four neighbours: a reading the sensor gave), ``hits``).  The statistics of
    level, spread and the rest see the repaired readings: a lost sample is counted once,
    as a dropout, not again as a burst of noise in one cell."""
    out = np.zeros(x.shape + (2,), np.float32)
    runs = [r for r in runs if r.size >= 3]
    if not runs or x.size == 0:
        return x, out
    order = np.concatenate(runs)
    sizes = np.array([r.size for r in runs])
    first = np.cumsum(np.r_[0, sizes[:-1]])
    run_of = np.repeat(np.arange(len(runs)), sizes)
    xo = x[order].astype(np.float64)
    with np.errstate(invalid='ignore'):
        ends = (np.nanmin(xo, axis=0), np.nanmax(xo, axis=0))
    at = [xo == v[None, :] for v in ends]
    rows = np.flatnonzero((at[0] | at[1]).any(axis=1))      # few: the extremes
    neighbours = _neighbours(run_of, first, sizes)
    near = np.abs(xo[rows] - _local(xo, neighbours[:, rows])) >= AWAY
    repaired = x
    for k in np.flatnonzero(((at[0][rows] | at[1][rows]) & near).any(axis=0)):
        around = xo[:, k][neighbours]                          # (4, N)
        d = np.abs(xo[:, k] - _local(xo[:, k], neighbours))
        scale = _scales(d, run_of, first, sizes)
        # a light that sweeps past moves the neighbours too: the jump must stand
        # ``STEADY`` times above the neighbours' own changes
        rough = np.max(np.abs(np.diff(around, axis=0)), axis=0)
        far = (d >= AWAY) & (d >= SPREADS * scale[run_of]) & (d >= STEADY * rough)
        lost = np.zeros(xo.shape[0], bool)
        for end in (0, 1):
            mark = at[end][:, k] & far
            out[order[mark], k, end] = 1.0
            lost |= mark
        if lost.any():
            if repaired is x:
                repaired = x.copy()
            repaired[order[lost], k] = np.sort(around[:, lost], axis=0)[1]
    return repaired, out


def _neighbours(run_of, first, sizes) -> np.ndarray:
    """(4, N) indices of each sample's neighbours within its run (reflected at the
    run's ends), samples ordered run by run."""
    start, n = first[run_of], sizes[run_of]
    j = (np.arange(run_of.size) - start)[None, :] + np.array(NEAR)[:, None]
    j = np.where(j < 0, -j, j)
    j = np.where(j >= n, 2 * (n - 1) - j, j)
    return start + np.clip(j, 0, n - 1)


def _local(xo: np.ndarray, neighbours: np.ndarray) -> np.ndarray:
    """(N, ...) the median of each sample's four neighbours (sum less the extremes)."""
    v = xo[neighbours]                                   # (4, N, ...)
    return 0.5 * (v.sum(axis=0) - v.max(axis=0) - v.min(axis=0))


def _scales(d: np.ndarray, run_of, first, sizes) -> np.ndarray:
    """Per run: 1.4826 x the median of ``d`` (absolute differences from the local level)
    over the run (one sort of all runs together, kept apart by an offset)."""
    d = np.where(np.isfinite(d), d, 0.0)
    offset = run_of * (d.max() + 1.0)
    v = np.sort(d + offset) - offset          # run_of is sorted: groups stay in place
    return 1.4826 * 0.5 * (v[first + (sizes - 1) // 2] + v[first + sizes // 2])


def repair_episodes(rec):
    """(``rec`` with its closed-loop dropouts repaired (see ``repair``), {'dropped':
    (episodes, 8, 2) counts of ``hits``}), episodes in ``np.unique`` order (the
    closed-loop blocks)."""
    episodes, ep = np.unique(rec.episode, return_inverse=True)
    order = np.lexsort((rec.step, ep))
    runs = np.split(order, np.flatnonzero(np.diff(ep[order])) + 1)
    raw = rec.readings[:, :8]
    readings, marks = repair(raw, runs)
    out = np.zeros((episodes.size, 8, 2))
    np.add.at(out, ep, marks)
    if readings is not raw:
        full = rec.readings.copy()
        full[:, :8] = readings
        rec = dataclasses.replace(rec, readings=full)
    return rec, {'dropped': out}


def closed_loop_stats(b, sums: np.ndarray, s: int, c: str) -> tuple[list, list]:
    """Keys and columns of the closed-loop dropout shares of stratum ``s`` (condition c)."""
    n = b.part(sums, 'n')[:, s, 0]
    pairs = shares('closed_loop_dropout', tuple(range(8)), c,
                   b.part(sums, 'dropped')[:, s] / n[:, None, None])
    return [k for k, _ in pairs], [v for _, v in pairs]


def shares(family: str, channels, condition, share: np.ndarray) -> list:
    """[(key, (R,) column)]: the share of dropouts per sensor and end (``share``: (R, C,
    2)), and pooled over the sensors (a small rate shared by many sensors shows there,
    as a limit's pile does)."""
    out = []
    for j, end in enumerate(ENDS):
        for k, sensor in enumerate(channels):
            out.append((Key(family, (sensor,), condition, end), share[:, k, j]))
        if len(channels) > 1:
            out.append((Key(family, tuple(channels), condition, end), share[:, :, j].mean(axis=1)))
    return out
