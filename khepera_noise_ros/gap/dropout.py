"""Isolated readings stuck at a sensor's lowest or highest value, far from their neighbours.

A dropout is a lost sample: the converter reads zero, or the top of its scale, for
one step, whatever the light.  Its fingerprint is a reading at the sensor's extreme
value (its lowest or highest over the recording: 0 or the scale's top once it has
dropouts, whatever the scale) lying far from the *local* level, the median of the two
readings before and the two after it in the same episode: by ``AWAY`` readings, by
``SPREADS`` robust sds of the episode's readings about their local levels, and by
``STEADY`` times the range of those neighbours.  The local level follows a slow drift,
a heading change and a closed-loop robot's turns; the robust sd grows with a spread
law or a group's shared noise beside it; a gain moves a run's level, not its single
readings.  A floor or ceiling, or a lamp's saturation, holds readings at the extreme
for stretches: such a value is a limit, not a dropout value.  A value standing apart
from every other reading of the sensor (``_detached``) is beyond the noise's reach
however wide it is, so its isolated readings need only lie ``AWAY`` from their level.

``repair`` marks them and reads each as its neighbours' level; ``prepared`` does so once
per recording (``Target`` and its simulations) and remembers the marks.  The gap
statistics compare their share per sensor and end (family ``dropout`` for stationary
recordings, ``closed_loop_dropout`` for closed-loop ones) and see everything else on
the repaired readings; ``gap.limits`` counts them to fit ``saturation_quantization``'s
dropout.
"""
from __future__ import annotations

import dataclasses
import warnings
import weakref

import numpy as np

from . import replay
from .blocks import Key

ENDS = ('to the lowest reading', 'to the highest reading')
AWAY = 10.0          # readings: a dropout lies at least this far from the local level
SPREADS = 6.0        # ... and this many robust sds of the run (a normal tail: ~2e-9)
NEAR = (-2, -1, 1, 2)    # the neighbours whose median is the local level
STEADY = 2.0         # ... and this many times the range of the neighbours
ISOLATED = 3         # of the four neighbours, at most one is at the same extreme
STRETCHED = 0.25     # a value whose readings lie next to each other this often is a limit
WINDOW = tuple(k for k in range(-8, 9) if k)   # a quick sd from these neighbours ...
QUICK = 0.75         # ... rules out, with a margin, readings the run's sd would (cheaper)
FAMILIES = frozenset({'dropout', 'closed_loop_dropout'})
# a value standing apart (``_detached``): this many readings at it, a gap to the next value
# inward this many times the widest of the next SPACINGS gaps inward (and AWAY readings)
DETACHED_HITS = 3
DETACHED = 3.0
SPACINGS = 10


def hits(x: np.ndarray, runs: list, moving: bool = False) -> np.ndarray:
    """(N, C, 2) float32: 1 where sample t of channel k is an isolated reading at the
    channel's lowest (end 0) or highest (end 1) finite value; ``runs``: sample indices
    of each run in step order (runs shorter than 3 samples have no neighbours)."""
    return repair(x, runs, moving)[1]


def repair(x: np.ndarray, runs: list,
           moving: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(``x`` with each dropout read as a neighbour's level (the lower of the middle two
    of its four neighbours: a reading the sensor gave), ``hits``, (C, 2) each channel's
    lowest and highest value).  Everything but the dropout statistics sees the repaired
    readings: a lost sample is counted once, as a dropout, not again as a burst of noise
    in one cell, a fall in a run's mean or a jump in its first differences.  Only the
    readings at an extreme are looked at (most recordings have few).  ``moving``: the
    light moves within a run (closed loop), so a value held for stretches is a limit the
    light reaches (``_stretched``); in a stationary run the light is steady and a lone
    reading far from it is a dropout whatever the value."""
    out = np.zeros(x.shape + (2,), np.float32)
    geometry = _geometry(runs, x.shape[0])
    if geometry is None or x.size == 0:
        return x, out, np.full((x.shape[1], 2), np.nan)
    xt = np.ascontiguousarray(x.T)   # channel by channel: 3x faster than down the columns
    finite = False
    if np.isnan(x).any():
        with np.errstate(invalid='ignore'), warnings.catch_warnings():
            warnings.simplefilter('ignore', RuntimeWarning)     # a channel all NaN
            ends = np.stack([np.nanmin(x, axis=0), np.nanmax(x, axis=0)], axis=1)
    else:
        ends = np.stack([xt.min(axis=1), xt.max(axis=1)], axis=1)
        finite = bool(np.isfinite(ends).all())      # no NaN, no infinity: every reading
    order, sizes, first, run_of, place = geometry
    repaired = x
    hits = [np.nonzero(xt == ends[:, end, None]) for end in (0, 1)]   # one pass each
    # hits come channel by channel: each channel's are a slice
    bounds = [np.searchsorted(h[0], np.arange(x.shape[1] + 1)) for h in hits]
    todo = []                                       # (channel, end, positions)
    for k in range(x.shape[1]):
        for end in (0, 1):
            i = place[hits[end][1][bounds[end][k]:bounds[end][k + 1]]]
            i = np.sort(i[i >= 0])
            if i.size == 0 or (moving and _stretched(i, run_of)):
                continue
            i = i[~_flanked(i, run_of)]
            if i.size:
                todo.append((k, end, i))
    if not todo:
        return repaired, out, ends
    # the per-reading tests for every channel at once: most readings at an extreme are a
    # noise tail's, near their neighbours; only what is left needs its run's scale
    at = np.concatenate([i for _, _, i in todo])
    k_at = np.concatenate([np.full(i.size, k) for k, _, i in todo])
    near, lower, d, alone = _local_test(x, at, k_at, run_of, first, sizes, order)
    cols: dict = {}       # per channel: readings run by run, distances from local levels
    cuts = np.cumsum([i.size for *_, i in todo])[:-1]
    for (k, end, i), keep, low, dist, apart in zip(
            todo, *(np.split(v, cuts) for v in (near, lower, d, alone))):
        # a value standing apart from all the sensor's other readings is no noise tail
        # however wide the noise, nor a level a moving light reaches: its readings need
        # only be isolated and ``AWAY`` from their neighbours
        loose = (apart & ~keep).any() and _detached(
            xt[k], end, hits[end], k, finite, bounds[end][k + 1] - bounds[end][k])
        if loose:
            keep = apart
        if not keep.any():
            continue
        if k not in cols:     # the local levels (both ends of a channel share them)
            col = xt[k][order].astype(np.float64)
            cols[k] = (col, _deviations(col, run_of, first, sizes))
        i, low = i[keep], low[keep]
        far = np.ones(i.size, bool) if loose else \
            _scaled(cols[k][0], i, dist[keep], run_of, first, sizes, cols[k][1])
        out[order[i[far]], k, end] = 1.0
        if far.any():
            if repaired is x:
                repaired = x.copy()
            repaired[order[i[far]], k] = low[far]
    return repaired, out, ends


def _stretched(i: np.ndarray, run_of: np.ndarray) -> bool:
    """Do the readings at a value (positions ``i``, sorted) come in stretches: more than
    ``STRETCHED`` of them next to another one in the same run?  The light itself holds a
    sensor at a limit (a lamp saturating it) for stretches, and a single step's visit
    there is then no dropout; dropouts at a rate p lie next to each other about 2p of
    the time."""
    pair = _adjacent(i, run_of)
    beside = np.zeros(i.size, bool)
    beside[1:] |= pair
    beside[:-1] |= pair
    return beside.sum() > STRETCHED * i.size


def _adjacent(i: np.ndarray, run_of: np.ndarray) -> np.ndarray:
    """(len(i) - 1,) whether positions ``i[j]`` and ``i[j + 1]`` (sorted) are consecutive
    samples of one run."""
    return (np.diff(i) == 1) & (run_of[i[1:]] == run_of[i[:-1]])


def _near_level(value: np.ndarray, around: np.ndarray) -> tuple:
    """(far: isolated and ``AWAY`` and ``STEADY`` times the neighbours' range from the
    local level, the lower middle of the neighbours, the distance, isolated and ``AWAY``)
    of readings ``value`` (M,) with neighbours ``around`` (4, M)."""
    # neighbours at the same extreme (a second dropout next to this one) are left out
    # of the local level and of the neighbours' range
    around = np.where(around == value[None, :], np.nan, around.astype(np.float64))
    count = np.isfinite(around).sum(axis=0)
    level, lower = _middle(around)
    d = np.abs(value - level)
    # a light that sweeps past, or a heading change, moves the neighbours too: the
    # jump must stand ``STEADY`` times above the range of the neighbours left
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', RuntimeWarning)    # none left: not isolated
        rough = np.nanmax(around, axis=0) - np.nanmin(around, axis=0)
    with np.errstate(invalid='ignore'):
        alone = (count >= ISOLATED) & (d >= AWAY)
        far = alone & (d >= STEADY * rough)
    return far, lower, d, alone


def _quick_spread(near: np.ndarray) -> np.ndarray:
    """1.4826 x the median absolute deviation of each column of ``near`` (the WINDOW)."""
    return 1.4826 * np.median(np.abs(near - np.median(near, axis=0)), axis=0)


def _flanked(i: np.ndarray, run_of: np.ndarray) -> np.ndarray:
    """Which readings at a value (positions ``i``, sorted) have the samples just before
    and after them in the same run at that value too: two of four neighbours alike, so
    never isolated (``ISOLATED``).  Dropping them first spares the tests a sensor's long
    clipped stretches (the same answer, found cheaper)."""
    pair = _adjacent(i, run_of)
    both = np.zeros(i.size, bool)
    both[1:-1] = pair[:-1] & pair[1:]
    return both


def _far(col, i, run_of, first, sizes) -> tuple[np.ndarray, np.ndarray]:
    """(which of the readings at positions ``i`` of one channel ``col`` are isolated and
    far from their local level, the lower middle of their neighbours)."""
    far, lower, d, _ = _local_test(col[:, None], i, np.zeros(i.size, np.int64), run_of,
                                   first, sizes)
    if far.any():
        far[far] = _scaled(col, i[far], d[far], run_of, first, sizes)
    return far, lower


def _local_test(xo, at, k, run_of, first, sizes, order=None) -> tuple:
    """``_near_level`` of the readings at positions ``at`` of channels ``k`` (``xo``: samples
    run by run, or in any order with ``order`` the samples run by run: only the readings
    asked for are gathered), then a quick robust sd from the ``WINDOW`` around those
    still far: it rules out, with a margin, readings their run's scale would.  Returns
    (far by both, the lower middle, the distance, isolated and ``AWAY`` from the local
    level)."""
    def rows(p):
        return p if order is None else order[p]
    far, lower, d, alone = _near_level(
        xo[rows(at), k], xo[rows(_neighbours(run_of, first, sizes, NEAR, at)), k])
    if far.any():
        near = xo[rows(_neighbours(run_of, first, sizes, WINDOW, at[far])), k[far]]
        far[far] = d[far] >= QUICK * SPREADS * _quick_spread(near.astype(np.float64))
    return far, lower, d, alone


def _detached(col: np.ndarray, end: int, at_end: tuple, k: int, finite: bool = False,
              count: int | None = None) -> bool:
    """Does channel ``k``'s extreme value (``end``) stand apart: at least ``DETACHED_HITS``
    readings at it (``at_end``: the (channel, sample) hits at that end), and a gap to the
    next value inward of ``AWAY`` readings and ``DETACHED`` times the widest gap between
    the next ``SPACINGS`` distinct values inward?  A noise tail thins out value by value
    and a lattice's gaps are all alike; readings lost to one value beyond the reach of
    the noise (525 beside a dark level of 500 whose noise stops at 510) leave a gap;
    ``finite``: every reading of ``col`` is known to be finite; ``count``: the hits of
    channel ``k`` in ``at_end``, if known."""
    if (np.count_nonzero(at_end[0] == k) if count is None else count) < DETACHED_HITS:
        return False
    x = col if finite else col[np.isfinite(col)]
    if end == 0:
        low = x.min()
        rest = x[x > low]
    else:       # the same values as negating every reading first, fewer negated
        low = -x.max()
        rest = -x[x < -low]
    m = min(rest.size, 64 * (SPACINGS + 1))
    if m < SPACINGS + 1:
        return False
    near = np.unique(np.partition(rest, m - 1)[:m])[:SPACINGS + 1]
    if near.size < 3:
        return False
    gap = near[0] - low
    return bool(gap >= AWAY and gap >= DETACHED * np.diff(near).max())


def _scaled(col, i, d, run_of, first, sizes, deviations=None) -> np.ndarray:
    """Which readings at positions ``i``, ``d`` from their local level, lie ``SPREADS``
    robust sds of their run (about its local levels) away; ``deviations``: every
    reading's distance from its local level (``_deviations``), if known."""
    scale = _scales(col, run_of, first, sizes, np.unique(run_of[i]), deviations)
    return d >= SPREADS * scale[run_of[i]]


_GEOMETRY: dict = {}


def _geometry(runs: list, samples: int):
    """(order, sizes, first, run_of, place) of the runs of at least 3 samples: the samples
    run by run, each run's size and first position, each position's run, each sample's
    position (-1: in no such run); None if there is no such run.  The same for every
    replay of a protocol (they share ``episodes``' list), so made once per list."""
    hit = _GEOMETRY.get(id(runs))
    if hit is not None and hit[0] is runs and hit[1] == samples:
        return hit[2]
    kept = [r for r in runs if r.size >= 3]
    out = None
    if kept:
        order = np.concatenate(kept)
        sizes = np.array([r.size for r in kept])
        first = np.cumsum(np.r_[0, sizes[:-1]])
        run_of = np.repeat(np.arange(len(kept)), sizes)
        place = np.full(samples, -1)
        place[order] = np.arange(order.size)        # sample -> position, run by run
        out = (order, sizes, first, run_of, place)
    if len(_GEOMETRY) > 32:
        _GEOMETRY.clear()
    _GEOMETRY[id(runs)] = (runs, samples, out)
    return out


_NEIGHBOURS: dict = {}


def _deviations(col, run_of, first, sizes) -> np.ndarray:
    """Every reading's distance from its local level (0 where not finite), run by run;
    the neighbours' positions are the same for every replay of a protocol (made once)."""
    key = (id(run_of), id(first), id(sizes))
    hit = _NEIGHBOURS.get(key)
    if hit is None or hit[0] is not run_of or hit[1] is not first or hit[2] is not sizes:
        if len(_NEIGHBOURS) > 8:
            _NEIGHBOURS.clear()
        hit = _NEIGHBOURS[key] = (run_of, first, sizes,
                                  _neighbours(run_of, first, sizes, NEAR))
    d = np.abs(col - _local(col, hit[3]))
    return np.where(np.isfinite(d), d, 0.0)


_EPISODES: dict = {}

# Recordings repaired by ``prepared``: id(readings) -> (marks, ends), dropped with them
_KNOWN: dict = {}


def prepared(rec):
    """``rec`` with its dropouts repaired (a copy; ``rec`` itself when it has none or was
    prepared already); the marks and extremes are remembered for the statistics and the
    fit (``known``) as long as the readings live."""
    if id(rec.readings) in _KNOWN:
        return rec
    repaired, marks, ends = repair(rec.readings, episodes(rec),
                                   replay.kind(rec) == 'closed_loop')
    if repaired is not rec.readings:
        rec = dataclasses.replace(rec, readings=repaired)
    key = id(rec.readings)
    _KNOWN[key] = (marks, ends)
    weakref.finalize(rec.readings, _KNOWN.pop, key, None)
    return rec


def known(readings: np.ndarray):
    """(marks (N, C, 2), ends (C, 2)) of readings ``prepared`` made, else None."""
    return _KNOWN.get(id(readings))


def episodes(rec) -> list:
    """Sample indices of each episode in step order: the runs a dropout is judged in.  A
    stationary episode is one continuous run through its headings, so a reading that
    lags a heading change (a latency) sits between its neighbours' levels, not apart."""
    key = (id(rec.episode), id(rec.step))
    hit = _EPISODES.get(key)         # replays of a protocol share its index columns
    if hit is not None and hit[0] is rec.episode and hit[1] is rec.step:
        return hit[2]
    _, ep = np.unique(rec.episode, return_inverse=True)
    order = np.lexsort((rec.step, ep))
    out = np.split(order, np.flatnonzero(np.diff(ep[order])) + 1)
    _EPISODES[key] = (rec.episode, rec.step, out)
    if len(_EPISODES) > 32:
        _EPISODES.pop(next(iter(_EPISODES)))
    return out


def columns(rec, channels) -> tuple[np.ndarray, np.ndarray]:
    """(readings of ``channels`` as float, repaired, and their dropout marks): those
    ``prepared`` remembered, else found now.  For every channel in order, the arrays
    themselves where they are float already (no copy: read them, do not write)."""
    every = list(channels) == list(range(rec.readings.shape[1]))
    cols = slice(None) if every else list(channels)
    x = rec.readings[:, cols].astype(np.float64, copy=False)
    done = known(rec.readings)
    if done is not None:
        return x, done[0][:, cols]
    return repair(x, episodes(rec))[:2]


def _neighbours(run_of, first, sizes, offsets=NEAR, at=None) -> np.ndarray:
    """(len(offsets), N) indices of each sample's (or each of ``at``'s) neighbours within
    its run (reflected at the run's ends), samples ordered run by run."""
    at = np.arange(run_of.size) if at is None else at
    start, n = first[run_of[at]], sizes[run_of[at]]
    j = (at - start)[None, :] + np.array(offsets)[:, None]
    j = np.where(j < 0, -j, j)
    j = np.where(j >= n, 2 * (n - 1) - j, j)
    return start + np.clip(j, 0, n - 1)


def _middle(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(median, lower middle) over axis 0 of the finite values of ``v`` (NaN where none)."""
    kept = np.sort(v, axis=0)                                   # NaN sorts last
    count = np.isfinite(kept).sum(axis=0)
    cols = np.arange(v.shape[1])
    lower = kept[np.maximum(count - 1, 0) // 2, cols]
    return 0.5 * (lower + kept[np.minimum(count // 2, v.shape[0] - 1), cols]), lower


def _scales(col, run_of, first, sizes, wanted, deviations=None) -> np.ndarray:
    """Per run (only the ``wanted`` ones; others inf): 1.4826 x the median absolute
    difference of its readings from their local levels (one partition of those runs
    together, kept apart by an offset: the middle values a sort would put there)."""
    out = np.full(sizes.size, np.inf)
    n = sizes[wanted]
    start = np.cumsum(np.r_[0, n[:-1]])
    i = np.arange(n.sum()) + np.repeat(first[wanted] - start, n)     # the runs' samples
    if deviations is None:
        d = np.abs(col[i] - _local(col, _neighbours(run_of, first, sizes, NEAR, i)))
        d = np.where(np.isfinite(d), d, 0.0)
    else:
        d = deviations[i]
    offset = run_of[i] * (d.max() + 1.0)
    middle = np.unique(np.r_[start + (n - 1) // 2, start + n // 2])
    v = np.partition(d + offset, middle) - offset     # runs in order: each keeps its place
    out[wanted] = 1.4826 * 0.5 * (v[start + (n - 1) // 2] + v[start + n // 2])
    return out


def _local(xo: np.ndarray, neighbours: np.ndarray) -> np.ndarray:
    """(N, ...) the median of each sample's four neighbours (sum less the extremes)."""
    v = xo[neighbours]                                   # (4, N, ...)
    return 0.5 * (v.sum(axis=0) - v.max(axis=0) - v.min(axis=0))


def repair_episodes(rec):
    """(``rec`` with its closed-loop dropouts repaired (see ``repair``), {'dropped':
    (episodes, 8, 2) counts of ``hits``}), episodes in ``np.unique`` order (the
    closed-loop blocks)."""
    labels, ep = np.unique(rec.episode, return_inverse=True)
    done = known(rec.readings)
    if done is None:
        raw = rec.readings[:, :8]
        readings, marks, _ = repair(raw, episodes(rec), moving=True)
        if readings is not raw:
            full = rec.readings.copy()
            full[:, :8] = readings
            rec = dataclasses.replace(rec, readings=full)
    else:
        marks = done[0][:, :8]
    out = np.zeros((labels.size, 8, 2))
    np.add.at(out, ep, marks)
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
