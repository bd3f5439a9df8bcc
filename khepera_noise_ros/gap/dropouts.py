"""Dropouts: isolated readings at a sensor's lowest or highest value, far from their
neighbours, marked and repaired before any other statistic (the light's level read
instead); their shares, and the count test that judges rare counts against the replays."""
from __future__ import annotations

import warnings
from collections import Counter
from typing import Any, Sequence

import numpy as np

from ..effects.base import AnyArray, Array, Key

ENDS = ('to the lowest reading', 'to the highest reading')
AWAY, SPREADS, STEADY = 10.0, 6.0, 2.0
NEAR = (-2, -1, 1, 2)            # the neighbours whose median is the local level
WINDOW = tuple(k for k in range(-8, 9) if k)   # a quick robust sd first (cheaper) ...
QUICK = 0.75                     # ... rules out, with a margin, what the run's sd would
ISOLATED = 3                     # of the four neighbours, at most one at the same extreme
STRETCHED = 0.25                 # readings at a value next to each other this often: a limit
DETACHED_HITS, DETACHED, SPACINGS = 3, 3.0, 10
MIN_HITS, DROP_Z, MAX_RATE = 3, 4.0, 0.5
COUNT_SAMPLES, MAX_COPIES, KNOWN, EVENTS = 48_000, 20, 20, 2


class Runs:
    """The runs (of 3 samples or more) a dropout is judged in, as positions run by run."""

    def __init__(self, runs: list[np.ndarray], samples: int):
        kept = [r for r in runs if r.size >= 3]
        self.order = np.concatenate(kept) if kept else np.zeros(0, np.int64)
        self.sizes = np.array([r.size for r in kept], np.int64)
        self.first = np.cumsum(np.r_[0, self.sizes[:-1]]).astype(np.int64)
        self.run_of = np.repeat(np.arange(len(kept)), self.sizes)
        self.place = np.full(samples, -1)
        self.place[self.order] = np.arange(self.order.size)
        self.near = self.order[_neighbours(self, NEAR)]     # (4, N) each one's NEAR samples


def repair(x: Array, runs: Runs, moving: bool = False) -> tuple[Array, AnyArray, Array]:
    """(``x`` with each dropout read as a neighbour's level, (N, C, 2) marks at the lowest
    and highest value, (C, 2) extremes); ``moving``: the light moves within a run."""
    marks = np.zeros(x.shape + (2,), np.float32)
    xt = np.ascontiguousarray(x.T)        # channel by channel: far faster than by column
    ends, gaps = _extremes(xt)
    if not runs.order.size or x.size == 0:
        return x, marks, ends
    xt = xt.astype(np.float64, copy=False)
    # every channel's readings at its extremes, by (channel, end) and position
    places = [runs.place[np.flatnonzero(xt[g // 2] == ends[g // 2, g % 2])]
              for g in range(2 * x.shape[1])]
    found = [np.sort(at[at >= 0]) for at in places]
    group = np.repeat(np.arange(len(found)), [i.size for i in found])
    at = np.concatenate(found)
    if moving:             # a value held for stretches is a limit the light reaches
        held = [g for g in np.unique(group) if _stretched(at[group == g], runs.run_of)]
        keep = ~np.isin(group, held)
        group, at = group[keep], at[keep]
    keep = ~_flanked(at, runs.run_of, group)
    group, at = group[keep], at[keep]
    if not at.size:
        return x, marks, ends
    local = _local if gaps or not np.isfinite(ends).all() else _local_finite
    far, lower, d, alone = local(xt, at, group, ends, runs)
    repaired, scales = x, {}
    for g in np.unique(group[alone]):             # far lies within alone
        mine = group == g
        k, end = divmod(int(g), 2)
        i, f, low, dist, apart = at[mine], far[mine], lower[mine], d[mine], alone[mine]
        if (apart & ~f).any() and _detached(xt[k], end):
            f = apart             # beyond the noise's reach: isolated and away suffices
        elif f.any():
            run = runs.run_of[i[f]]
            for r in np.unique(run):
                if (k, r) not in scales:
                    scales[(k, r)] = _scale(xt[k], runs, int(r))
            f[f] = dist[f] >= SPREADS * np.array([scales[(k, r)] for r in run.tolist()])
        if f.any():
            if repaired is x:
                repaired = x.copy()
            marks[runs.order[i[f]], k, end] = 1.0
            repaired[runs.order[i[f]], k] = low[f]
    return repaired, marks, ends


def _extremes(xt: Array) -> tuple[Array, bool]:
    """((C, 2) each row's least and greatest finite value, whether any value is NaN)."""
    if not np.isnan(xt).any():
        return np.stack([xt.min(axis=1), xt.max(axis=1)], axis=1), False
    with np.errstate(invalid='ignore'), warnings.catch_warnings():
        warnings.simplefilter('ignore', RuntimeWarning)         # a channel all NaN
        return np.stack([np.nanmin(xt, axis=1), np.nanmax(xt, axis=1)], axis=1), True


def _local(xt: Array, i: AnyArray, group: AnyArray, ends: Array,
           runs: Runs) -> tuple[AnyArray, ...]:
    """(far, the lower middle of the neighbours, distance, isolated and ``AWAY``) of the
    readings at positions ``i`` of channel and end ``group`` (``2 k + end``)."""
    k = group // 2
    value = xt[k, runs.order[i]]
    around = xt[k, runs.near[:, i]]
    around = np.where(around == value[None, :], np.nan, around)
    count = np.isfinite(around).sum(axis=0)
    kept = np.sort(around, axis=0)                              # NaN sorts last
    cols = np.arange(i.size)
    lower = kept[np.maximum(count - 1, 0) // 2, cols]
    level = 0.5 * (lower + kept[np.minimum(count // 2, 3), cols])
    d = np.abs(value - level)
    with warnings.catch_warnings(), np.errstate(invalid='ignore'):
        warnings.simplefilter('ignore', RuntimeWarning)        # none left: not isolated
        rough = np.nanmax(around, axis=0) - np.nanmin(around, axis=0)
        alone = (count >= ISOLATED) & (d >= AWAY)
        far = alone & (d >= STEADY * rough)
    return _far(xt, i, k, runs, far, d), lower, d, alone


def _local_finite(xt: Array, i: AnyArray, group: AnyArray, ends: Array,
                  runs: Runs) -> tuple[AnyArray, ...]:
    """``_local`` where every reading is finite (the same numbers where a reading is
    isolated): the neighbours sorted by a network, those at the reading (itself an
    extreme) first once the highest end is negated."""
    k, sign = group // 2, 1.0 - 2.0 * (group % 2)
    v = ends.ravel()[group] * sign
    a = xt.ravel()[k * xt.shape[1] + runs.near[:, i]] * sign
    count = 4 - np.count_nonzero(a == v, axis=0)
    s0, s1 = np.minimum(a[0], a[1]), np.maximum(a[0], a[1])
    s2, s3 = np.minimum(a[2], a[3]), np.maximum(a[2], a[3])
    s0, s2 = np.minimum(s0, s2), np.maximum(s0, s2)
    s1, s3 = np.minimum(s1, s3), np.maximum(s1, s3)
    s1, s2 = np.minimum(s1, s2), np.maximum(s1, s2)
    four = count == 4
    near = np.where(four, s1, s2)           # the middle pair: (near, s2), near = s2 of three
    d = np.abs(v - 0.5 * (near + s2))
    lower = np.where(sign > 0, near, -s2)
    rough = s3 - np.where(four, s0, s1)
    alone = (count >= ISOLATED) & (d >= AWAY)
    return _far(xt, i, k, runs, alone & (d >= STEADY * rough), d), lower, d, alone


def _far(xt: Array, i: AnyArray, k: AnyArray, runs: Runs, far: AnyArray, d: Array) -> AnyArray:
    """``far`` less the readings within ``QUICK`` of the reach of a quick robust sd."""
    if far.any():
        near = xt[k[far], runs.order[_neighbours(runs, WINDOW, i[far])]].T
        spread = 1.4826 * _median(np.abs(near - _median(near)[:, None]))
        far[far] = d[far] >= QUICK * SPREADS * spread
    return far


def _median(x: Array) -> Array:
    """``np.median(x, axis=1)`` by a sort of each short row (far quicker), NaN with one."""
    x = np.sort(x, axis=1)                                      # NaN sorts last
    n = x.shape[1]
    out: Array = np.where(np.isnan(x[:, -1]), np.nan, (x[:, (n - 1) // 2] + x[:, n // 2]) / 2)
    return out


def _neighbours(runs: Runs, offsets: tuple[int, ...], at: np.ndarray | None = None) -> np.ndarray:
    """(offsets, N) each position's neighbours in its run (reflected at its ends)."""
    at = np.arange(runs.run_of.size) if at is None else at
    start, n = runs.first[runs.run_of[at]], runs.sizes[runs.run_of[at]]
    j = np.abs((at - start)[None, :] + np.array(offsets)[:, None])
    j = np.where(j >= n, 2 * (n - 1) - j, j)
    out: np.ndarray = start + np.clip(j, 0, n - 1)
    return out


def _scale(col: Array, runs: Runs, r: int) -> float:
    """The robust sd of run ``r``'s deviations from the median of each reading's ``NEAR``
    neighbours (their sum less the extremes, halved)."""
    at = slice(runs.first[r], runs.first[r] + runs.sizes[r])
    v = col[runs.near[:, at]]
    dev = np.abs(col[runs.order[at]] - 0.5 * (v.sum(axis=0) - v.max(axis=0) - v.min(axis=0)))
    middle = ((dev.size - 1) // 2, dev.size // 2)       # np.median's, without its overhead
    dev = np.partition(np.where(np.isfinite(dev), dev, 0.0), middle)
    return float(1.4826 * ((dev[middle[0]] + dev[middle[1]]) / 2))


def _adjacent(i: np.ndarray, run_of: np.ndarray, group: np.ndarray | None = None) -> np.ndarray:
    """Are positions ``i[j]`` and ``i[j + 1]`` consecutive samples of one run (and group)?"""
    out: np.ndarray = (np.diff(i) == 1) & (run_of[i[1:]] == run_of[i[:-1]])
    return out if group is None else out & (group[1:] == group[:-1])


def _stretched(i: np.ndarray, run_of: np.ndarray) -> bool:
    """Do the readings at a value come in stretches (a limit the light holds)?"""
    pair = _adjacent(i, run_of)
    beside = np.r_[False, pair] | np.r_[pair, False]
    return bool(beside.sum() > STRETCHED * i.size)


def _flanked(i: np.ndarray, run_of: np.ndarray, group: np.ndarray) -> np.ndarray:
    """Readings whose two neighbours in the run are at the value too: never isolated."""
    pair = _adjacent(i, run_of, group)
    both = np.zeros(i.size, bool)
    both[1:-1] = pair[:-1] & pair[1:]
    return both


def _detached(col: Array, end: int) -> bool:
    """Does the extreme value stand apart from the next values inward, beyond the noise?"""
    x = col if np.isfinite(col).all() else col[np.isfinite(col)]
    x = x if end == 0 else -x
    low = x.min()
    rest = x[x > low]
    if rest.size < SPACINGS + 1 or rest.min() - low < AWAY \
            or np.count_nonzero(x == low) < DETACHED_HITS:
        return False
    m = min(rest.size, 64 * (SPACINGS + 1))     # the distinct values among the nearest m
    near = np.unique(np.partition(rest, m - 1)[:m])[:SPACINGS + 1]
    if near.size < 3:
        return False
    gap = near[0] - low
    return bool(gap >= AWAY and gap >= DETACHED * np.diff(near).max())


def shares(channels: Sequence[int], share: Array) -> list[Array]:
    """Dropout shares (R, C, 2) per sensor and end, and pooled over the sensors."""
    cols = []
    for j in range(len(ENDS)):
        cols.append(share[:, :, j])
        if len(channels) > 1:
            cols.append(share[:, :, j].mean(axis=1)[:, None])
    return cols


def share_keys(family: str, channels: tuple[int, ...], condition: str | None) -> list[Key]:
    out = []
    for end in ENDS:
        out += [Key(family, (sensor,), condition, end) for sensor in channels]
        if len(channels) > 1:
            out.append(Key(family, channels, condition, end))
    return out


# -- rare counts -----------------------------------------------------------------------

def counts(recordings: Sequence[Any]) -> dict[Key, list[float]]:
    """{Key: [count, readings]} of the dropout statistics of repaired recordings."""
    out: dict[Key, list[float]] = {}
    for r in recordings:
        rec, marks = r.recording, r.marks
        if r.kind == 'closed_loop':
            family, channels = 'closed_loop_dropout', tuple(range(min(8, marks.shape[1])))
            groups: list[tuple[str | None, Any]] = [
                (str(c), rec.condition == c) for c in np.unique(rec.condition)]
        else:
            family, channels = 'dropout', tuple(rec.channels_used)
            groups = [(None, np.ones(len(rec), bool))]
        for condition, rows in groups:
            hit = marks[rows].sum(axis=0)[list(channels)]
            n = float(np.count_nonzero(rows))
            values = np.concatenate([c[0] for c in shares(channels, hit[None] / n)])
            for key, value in zip(share_keys(family, channels, condition), values):
                width = len(channels) if len(key.sensors) > 1 else 1
                total = out.setdefault(key, [0.0, 0.0])
                total[0] += float(value) * n * width
                total[1] += n * width
    for v in out.values():
        v[0] = float(np.round(v[0]))
    return out


def count_copies(samples: int, copies: int) -> int:
    """Copies simulated for the counts: enough for ``COUNT_SAMPLES`` readings."""
    n = max(samples, 1)
    if n * copies >= COUNT_SAMPLES / 2:
        return copies
    return int(max(copies, min(MAX_COPIES, np.ceil(COUNT_SAMPLES / n))))


def undecided(real: dict[Key, list[float]], sim: dict[Key, list[float]]) -> bool:
    """``EVENTS`` or more real events beside fewer than ``KNOWN`` simulated ones?"""
    return any(r >= EVENTS and sim[key][0] < KNOWN for key, (r, _) in real.items() if key in sim)


def dropouts(real: Sequence[Any], sim: Sequence[Any]) -> dict[int, tuple[float, float]]:
    """{sensor: (value, rate)} with more dropouts than the replays ``sim`` (alone or pooled
    with sensors dropping out to the same value)."""
    if not real:
        return {}
    sensors = list(real[0].recording.channels_used)
    c = len(sensors)
    hits, total = np.zeros((c, 2)), np.zeros(c)
    expected, var = np.zeros((c, 2)), np.zeros((c, 2))
    votes = [[Counter[float](), Counter[float]()] for _ in sensors]
    for i, r in enumerate(real):
        h, n, values = _marked(r, sensors)
        hits += h
        total += n
        for k, v in enumerate(values):
            for end in (0, 1):
                if h[k, end]:
                    votes[k][end][float(v[end])] += h[k, end]
        if i < len(sim):
            hs, ns, _ = _marked(sim[i], sensors)
            copies = max(1.0, ns.max() / max(n.max(), 1.0))
            with np.errstate(invalid='ignore', divide='ignore'):
                e = np.where(ns[:, None] > 0, hs / ns[:, None] * n[:, None], 0.0)
            expected += e
            var += e + 1.0 / copies           # Poisson, and the simulator's own count
    out: dict[int, tuple[float, float]] = {}
    for end in (0, 1):
        excess = hits[:, end] - expected[:, end]
        alone = (hits[:, end] >= MIN_HITS) & (excess > DROP_Z * np.sqrt(var[:, end]))
        for k in map(int, np.flatnonzero(alone)):
            rate = float(excess[k] / total[k])
            if sensors[k] not in out or rate > out[sensors[k]][1]:
                out[sensors[k]] = (votes[k][end].most_common(1)[0][0], rate)
        by_value: dict[float, list[int]] = {}
        for k in map(int, np.flatnonzero(hits[:, end] > 0)):
            by_value.setdefault(votes[k][end].most_common(1)[0][0], []).append(k)
        for value, ks in by_value.items():
            if hits[ks, end].sum() >= MIN_HITS and len(ks) > 1 and \
                    excess[ks].sum() > DROP_Z * np.sqrt(var[ks, end].sum()):
                rate = float(excess[ks].sum() / total[ks].sum())
                for k in ks:
                    out.setdefault(sensors[k], (value, rate))
    return out


def seen_share(repaired: Sequence[Any], sensors: Sequence[int]) -> float:
    """The share of dropouts marked among the ``sensors``' readings."""
    hits = total = 0.0
    for r in repaired:
        h, n, _ = _marked(r, list(sensors))
        hits += h.sum()
        total += n.sum()
    return hits / max(total, 1.0)


def _marked(r: Any, sensors: list[int]) -> tuple[Array, Array, list[tuple[float, float]]]:
    """(hits (C, 2), readings (C,), [(low, high)] per sensor) of a repaired recording."""
    counted = np.isfinite(r.recording.readings[:, sensors]).sum(axis=0).astype(np.float64)
    return r.marks[:, sensors].sum(axis=0), counted, [tuple(r.ends[s]) for s in sensors]


def rescaled_rate(rate: float, real_share: float, sim_share: float) -> float:
    """A dropout rate scaled by the real over the simulated share seen."""
    if sim_share <= 0:
        return rate
    return round(float(np.clip(rate * real_share / sim_share, rate, MAX_RATE)), 5)
