"""The statistics of stationary recordings from per-block sums: per cell (condition,
heading) and per condition, over residuals about each run's mean."""
from __future__ import annotations

import functools
from typing import Any, Callable, Sequence, cast

import numpy as np
from scipy import sparse

from ..effects.base import AnyArray, Array, Key
from ..recording import Recording
from . import bootstrap
from . import protocol

LAGS = (1, 3)
STEP_LAGS = 3
SKIP = 3                  # first samples of a run left out of the own part
MIN_OWN = 3               # channels the own part needs (the others' mean of two is one sensor)
ROUNDING = 1e-10          # a spread below this share of the level: a constant sensor's rounding


def cells(rec: Recording) -> tuple[list[tuple[str, float | None]], np.ndarray]:
    """(labels in order of first appearance, cell of each sample)."""
    heading = np.round(rec.heading_deg, 1)
    conditions, cond = protocol.labels(rec.condition)
    pairs = np.stack([cond, np.where(np.isfinite(heading), heading, np.inf)], axis=1)
    unique, first, index = np.unique(pairs, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.argsort(order)                    # each cell's place in order of appearance
    labels = [(str(conditions[int(unique[i, 0])]),
               float(unique[i, 1]) if np.isfinite(unique[i, 1]) else None) for i in order]
    return labels, rank[index.ravel()]


def units(rec: Recording, cell: np.ndarray) -> list[np.ndarray]:
    """Sample indices of each (episode, cell) run, in step order."""
    order = np.lexsort((rec.step, cell, rec.episode))
    key = rec.episode[order] * (int(cell.max()) + 1 if cell.size else 1) + cell[order]
    return np.split(order, np.flatnonzero(np.diff(key)) + 1) if order.size else []


def block_length(rec: Recording, channels: list[int]) -> int:
    """The block-length rule over each run's residuals; at least 5 samples (a block carries
    spreads and lagged products), at most half the longest run."""
    runs_ = [r for r in units(rec, cells(rec)[1]) if r.size >= 2]
    if not runs_:
        return 5
    x = rec.readings[:, channels].astype(np.float64)
    y = np.concatenate([x[r] - x[r].mean(axis=0) for r in runs_])
    edges = np.cumsum([0] + [r.size for r in runs_])
    segments = [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]
    return bootstrap.block_length(y, segments, minimum=5,
                                  maximum=max(5, max(r.size for r in runs_) // 2))


class Grouping:
    """Sums of per-sample values (kept samples in block order) by group: blocks for a
    bootstrap, or whole strata where only the full data's sums are wanted (the same
    totals, a fraction of the work)."""

    def __init__(self, group: np.ndarray, size: int, strata: np.ndarray, of_block: np.ndarray,
                 lags: Sequence[tuple[np.ndarray, np.ndarray, bool]] = ()):
        self.size, self.strata, self.of_block, self.group = size, strata, of_block, group
        self.pick = sparse.csr_matrix((np.ones(group.size, np.float32),
                                       (group, np.arange(group.size))), shape=(size, group.size))
        self.count = np.bincount(group, minlength=size).astype(np.float64)[:, None]
        # per lag of ``_lag_pairs``: the number of samples with a partner, and where the
        # partners lie the lag's rows on, the sums of the products of rows that far apart
        self.lag_n = self(np.stack([hit for hit, _, _ in lags], axis=1).astype(np.float32)) \
            if lags else None
        self.lag_picks = [sparse.csr_matrix((np.ones(np.count_nonzero(hit[:-lag]), np.float32), (
            group[:-lag][hit[:-lag]], np.flatnonzero(hit[:-lag]))), shape=(size, group.size - lag))
            if shifted else None for (hit, _, shifted), lag in zip(lags, LAGS)]
        first = np.flatnonzero(np.r_[True, np.diff(group) != 0]) if group.size else group
        self.first, self.first_group = first, group[first]      # each group's first sample
        self.contiguous = np.unique(self.first_group).size == first.size
        length = np.diff(np.r_[first, group.size])
        self.segments = [(int(g), slice(a, a + n)) for g, a, n in zip(self.first_group, first,
                                                                      length)]
        # short groups (blocks): per position, the groups that have a sample there (all of
        # them in order: a slice, no scatter) and it
        whole = np.array_equal(self.first_group, np.arange(size))
        self.steps = [(slice(None) if whole and (length > k).all() else
                       self.first_group[length > k], first[length > k] + k)
                      for k in range(int(length.max()))] \
            if self.contiguous and first.size and length.max() <= 16 else None

    def __call__(self, values: Array) -> Array:
        out: Array = np.asarray(self.pick @ values.reshape(values.shape[0], -1))
        return out.reshape((self.size,) + values.shape[1:])

    def cross(self, y: Array) -> Array:
        """(groups, C (C + 1) / 2) sums of the products y_k y_m, k <= m: a matrix product per
        group where groups are few (whole strata), else the products summed."""
        i, j = np.triu_indices(y.shape[1])
        out = np.zeros((self.size, i.size), y.dtype)
        if len(self.segments) <= 64:
            for g, at in self.segments:
                out[g] = (y[at].T @ y[at])[i, j]
        elif self.steps is not None:    # as ``self`` adds them: sample by sample in order
            for groups, rows in self.steps:
                v = y[rows]
                out[groups] += v[:, i] * v[:, j]
        else:
            out = self(y[:, i] * y[:, j])
        return out


class Layout:
    """How a recording's samples fall into cells, runs and blocks: the same for every
    replay of a protocol with as many copies (replays share their index columns)."""

    def __init__(self, rec: Recording, length: int):
        self.labels, self.cell = cells(rec)
        runs = units(rec, self.cell)
        self.run_sizes = sizes = np.array([r.size for r in runs], np.int64)
        run_order, run = np.concatenate(runs), np.repeat(np.arange(len(runs)), sizes)
        self.run_of = np.empty(len(rec), np.int64)
        self.run_of[run_order] = run
        position = np.concatenate([np.arange(n) for n in sizes])
        key = run * (position.max() // length + 2) + position // length
        _, chunk = np.unique(key, return_inverse=True)
        keep = np.bincount(chunk)[chunk] >= 2            # a lone sample carries no spread
        kept, chunk = run_order[keep], np.unique(chunk[keep], return_inverse=True)[1]
        stratum_of_chunk = np.zeros(int(chunk.max()) + 1 if chunk.size else 0, np.int64)
        stratum_of_chunk[chunk] = self.cell[kept]
        rank = np.argsort(np.argsort(stratum_of_chunk, kind='stable'))   # blocks by stratum
        block = rank[chunk]
        by = np.argsort(block, kind='stable')
        self.order, block = kept[by], block[by]          # kept samples, block by block
        stratum = np.sort(stratum_of_chunk)
        strata = len(self.labels)
        self.lags = _lag_pairs(rec.step[self.order], self.run_of[self.order])
        self.by_block = Grouping(block, stratum.size, stratum, np.arange(stratum.size), self.lags)
        self.by_stratum = Grouping(stratum[block], strata, np.arange(strata), stratum, self.lags)
        block_of = np.full(len(rec), -1)
        block_of[self.order] = block
        self.changes = _changes(rec, runs, block_of)
        self.own_kept = np.zeros((len(rec), 1), np.float32)    # in sample order
        self.own_kept[run_order, 0] = position >= SKIP
        self.by_run = Grouping(self.run_of, len(runs), np.arange(len(runs)), np.arange(len(runs)))


def sums(lay: Layout, x: Array, total: Grouping) -> dict[str, Array]:
    """Sums by ``total``'s groups of the statistics of readings ``x`` (N, C)."""
    c = x.shape[1]
    run_mean = lay.by_run(x) / lay.run_sizes[:, None]
    y = x - run_mean[lay.run_of]
    yo = y[lay.order]
    out = {'n': total.count, 'sx': total(x[lay.order]), 's1': total(yo)}
    # products in single precision (a block's few hundred samples keep 6 digits)
    y32, own = yo.astype(np.float32), _own(y, lay)[lay.order]
    out.update({'s2': total.cross(y32), 's4': total(np.square(np.square(y32))),
                'own_s2': total(own * own)})
    for name, v in (('lag_s', y32), ('own_lag_s', own)):
        out[name] = np.stack([_lagged(v, total, k, *pair) for k, pair in enumerate(lay.lags)],
                             axis=1)
    out['lag_n'] = cast(Array, total.lag_n)
    at, samples, old, new = lay.changes
    dd, d2 = np.zeros((total.size, STEP_LAGS, c)), np.zeros((total.size, STEP_LAGS, c))
    if at.size:
        change = run_mean[old] - run_mean[new]
        np.add.at(dd, total.of_block[at], (x[samples] - run_mean[new][:, None, :])
                  * change[:, None, :])
        np.add.at(d2, total.of_block[at],
                  np.broadcast_to((change ** 2)[:, None, :], (at.size, STEP_LAGS, c)))
    out['step_dd'], out['step_d2'] = dd, d2
    return out                          # single precision parts: doubles once packed


def _lagged(v: Array, total: Grouping, k: int, hit: np.ndarray, partner: np.ndarray,
            shifted: bool) -> Array:
    """Sums of each sample's product with its partner ``LAGS[k]`` steps later; ``shifted``:
    the partners lie that many rows on (a run's blocks consecutive)."""
    pick = total.lag_picks[k]
    if pick is not None:       # the samples without a partner left out: they add nothing
        out: Array = np.asarray(pick @ (v[:-LAGS[k]] * v[LAGS[k]:]))
        return out
    products = np.zeros_like(v)
    products[hit] = v[hit] * v[partner[hit]]
    return total(products)


def own_part(y: AnyArray, ref: np.ndarray, by_run: Callable[[AnyArray], AnyArray],
             run_of: np.ndarray) -> AnyArray:
    """Each sensor's own part of the run residuals ``y`` (the one definition): less its
    per-run regression on the mean of the others among ``ref`` (a mask of the sensors);
    ``by_run``: per-run sums, ``run_of``: each row's run."""
    count = np.maximum(ref.sum() - ref, 1).astype(y.dtype)
    others = (y[:, ref].sum(axis=1, keepdims=True) - y * ref) / count
    cross, square = by_run(y * others), by_run(others * others)
    beta = np.divide(cross, square, out=np.zeros_like(cross), where=square > 0)
    out: AnyArray = y - beta.astype(y.dtype)[run_of] * others
    return out


def _own(y: Array, lay: Layout) -> Array:
    """``own_part`` of all the sensors, zero at the first ``SKIP`` samples of a run."""
    if y.shape[1] < MIN_OWN:
        return np.zeros_like(y)
    return own_part(y.astype(np.float32) * lay.own_kept, np.ones(y.shape[1], bool), lay.by_run,
                    lay.run_of)


def stats(b: bootstrap.Blocks, s: Array) -> tuple[list[Key], list[Array]]:
    """(keys, (R, k) columns) from the resampled (R, S, D) sums."""
    n = b.part(s, 'n')[..., 0]
    s1, c = b.part(s, 's1'), len(b.channels)
    i, j = np.triu_indices(c)
    s2 = np.zeros(s.shape[:2] + (c, c))
    s2[..., i, j] = s2[..., j, i] = b.part(s, 's2')
    centred = s2 - s1[..., :, None] * s1[..., None, :] / n[..., None, None]
    level = b.part(s, 'sx') / n[..., None]
    cell_sd = np.sqrt(np.diagonal(centred, axis1=-2, axis2=-1) / (n[..., None] - 1))
    conditions = tuple(dict.fromkeys(cond for cond, _ in b.strata))
    r = s.shape[0]
    cols = [np.stack([level, cell_sd], axis=3).reshape(r, -1)]
    pairs = np.triu_indices(c, 1)
    for cond in conditions:
        m = [i for i, lab in enumerate(b.strata) if lab[0] == cond]
        dof = (n[:, m] - 1).sum(axis=1)
        cov = centred[:, m].sum(axis=1) / dof[:, None, None]
        var = np.diagonal(cov, axis1=-2, axis2=-1)
        # a sensor that holds one value has no correlation, autocorrelation or kurtosis:
        # its sums leave rounding about the run's mean (readings not whole), or cancel a
        # little below zero (a bootstrap draw of whole readings), not noise
        mean = b.part(s, 'sx')[:, m].sum(axis=1) / n[:, m].sum(axis=1)[:, None]
        var = np.where(var > (ROUNDING * mean) ** 2, var, 0.0)
        sd = np.sqrt(var)
        cols.append((cov / (sd[:, :, None] * sd[:, None, :]))[:, pairs[0], pairs[1]])
        cols.append((b.part(s, 'lag_s')[:, m].sum(axis=1) / b.part(s, 'lag_n')[:, m].sum(
            axis=1)[..., None] / var[:, None, :]).reshape(r, -1))
        cols.append(b.part(s, 's4')[:, m].sum(axis=1) / n[:, m].sum(axis=1)[:, None] / var ** 2
                    - 3.0)
        if c >= MIN_OWN:
            cols.append((b.part(s, 'own_lag_s')[:, m].sum(axis=1) / b.part(s, 'own_s2')[
                :, m].sum(axis=1)[:, None, :]).reshape(r, -1))
    dl = level - level.mean(axis=1, keepdims=True)
    ds = cell_sd - cell_sd.mean(axis=1, keepdims=True)
    cols.append((dl * ds).sum(axis=1) / (dl * dl).sum(axis=1))
    d2 = b.part(s, 'step_d2').sum(axis=1)                             # (R, J, C)
    timed: tuple[bool, ...] = ()
    if (d2[0] > 0).any():
        response = b.part(s, 'step_dd').sum(axis=1) / d2
        ok = d2[0, 0] >= 100.0 * STEP_LAGS              # changes too small to time: left out
        cols.append(response[:, :, ok].transpose(0, 2, 1).reshape(r, -1))
        timed = tuple(bool(v) for v in ok)
    return keys(tuple(b.strata), b.channels, timed), cols


@functools.lru_cache(maxsize=64)
def keys(strata: tuple[tuple[str, float | None], ...], ch: tuple[int, ...],
         timed: tuple[bool, ...]) -> list[Key]:
    """The keys of ``stats``, in its column order: the same for every replay of a protocol
    (a shared list: never modify it)."""
    out = [Key(family, (k,), cond, None if h is None else f'heading {h:g} deg')
           for cond, h in strata for k in ch for family in ('level', 'spread')]
    pairs = [(ch[i], ch[j]) for i in range(len(ch)) for j in range(i + 1, len(ch))]
    for cond in dict.fromkeys(cond for cond, _ in strata):
        out += [Key('correlation', p, cond, None) for p in pairs]
        out += [Key('autocorrelation', (k,), cond, f'lag {lag}') for lag in LAGS for k in ch]
        out += [Key('kurtosis', (k,), cond, None) for k in ch]
        if len(ch) >= MIN_OWN:
            out += [Key('own_autocorrelation', (k,), cond, f'lag {lag}') for lag in LAGS
                    for k in ch]
    out += [Key('spread_vs_level', (k,), None, None) for k in ch]
    return out + [Key('step_response', (k,), None, f'sample {j} after a change')
                  for k, ok in zip(ch, timed) if ok for j in range(STEP_LAGS)]


def _lag_pairs(steps: np.ndarray, run: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, bool]]:
    """Per lag, (hit, partner, shifted): samples with a partner ``lag`` steps later in their
    run, and whether every partner lies ``lag`` rows on."""
    if not steps.size:
        return [(np.zeros(0, bool), np.zeros(0, np.int64), False) for _ in LAGS]
    key = run.astype(np.int64) * (int(steps.max()) + max(LAGS) + 2) + steps
    sorter = np.argsort(key)
    out = []
    for lag in LAGS:
        partner = sorter[np.minimum(np.searchsorted(key, key + lag, sorter=sorter), key.size - 1)]
        hit = key[partner] == key + lag
        out.append((hit, partner, partner.size > lag and np.array_equal(
            partner[:-lag][hit[:-lag]], np.flatnonzero(hit[:-lag]) + lag)))
    return out


def _changes(rec: Recording, runs: list[np.ndarray], block_of: np.ndarray) -> tuple[Any, ...]:
    """(block, first ``STEP_LAGS`` samples, old run, new run) of every change of heading
    between consecutive runs of an episode without a gap."""
    by_start = sorted(range(len(runs)),
                      key=lambda i: (int(rec.episode[runs[i][0]]), int(rec.step[runs[i][0]])))
    out = []
    for i, j in zip(by_start[:-1], by_start[1:]):
        old, new = runs[i], runs[j]
        b = block_of[new[0]]
        if rec.episode[old[0]] == rec.episode[new[0]] and b >= 0 and \
                rec.step[new[0]] == rec.step[old[-1]] + 1 and new.size > STEP_LAGS:
            out.append((b, new[:STEP_LAGS], i, j))
    if not out:
        return (np.zeros(0, np.int64),) * 4
    return tuple(np.array(column) for column in zip(*out))


def blocks(rec: Recording, x: Array, lay: Layout, total: Grouping,
           more: dict[str, Array]) -> bootstrap.Blocks:
    """The ``Blocks`` of a stationary recording: its sums by ``total`` and ``more``."""
    table, layout = bootstrap.pack({**sums(lay, x, total), **more})
    return bootstrap.Blocks('stationary', tuple(rec.channels_used), lay.labels, total.strata,
                            table, layout)
