"""The statistics the gap diagnosis compares, with block-bootstrap replicates.

A recording is cut into *blocks* (stationary data: contiguous runs of samples
within one episode at one heading; closed-loop data: whole episodes), and each
block is reduced to sufficient sums (counts, sums of residuals, cross products,
lagged products, indicator counts, regression moments).  Every statistic is a
smooth function of those sums added up per *stratum* (a cell = condition and
heading, or a condition).  Resampling blocks with replacement within each
stratum then costs one small matrix product per replicate set, and it keeps the
autocorrelation inside blocks, which an i.i.d. bootstrap would destroy.

A statistic is named by a ``Key``: family, sensors, condition, part.  Real and
simulated data of the same protocol give the same keys, so they line up.
"""
from __future__ import annotations

import functools
from collections import OrderedDict

import numpy as np

from ..recording import Recording
from . import blockcounts, blocklength, blocksums, dropout, ownpart, pileup
from .blocks import FACTORS, MODULI, Blocks, Key, Stats, pack  # noqa: F401 (re-exported)
from .closedloop import closed_loop_blocks as _closed_loop_blocks, closed_loop_stats
from .resample import resampled, stratum_sums, weights  # noqa: F401 (re-exported)

LAGS = (1, 3)                    # autocorrelation lags, in steps
STEP_LAGS = 3                    # samples after a heading change in the step response
REPLICATES = 200


# -- stationary ---------------------------------------------------------------------------

def cells(rec: Recording) -> tuple[list, np.ndarray]:
    """(labels, index per sample): a cell is a (condition, heading) pair."""
    heading = np.round(rec.heading_deg, 1)
    known = np.isfinite(heading)
    conditions, cond = np.unique(rec.condition, return_inverse=True)
    pairs = np.stack([cond, np.where(known, heading, np.inf)], axis=1)
    unique, first, index = np.unique(pairs, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)                       # labels in order of first appearance
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    labels = [(str(conditions[int(unique[i, 0])]),
               float(unique[i, 1]) if np.isfinite(unique[i, 1]) else None) for i in order]
    return labels, rank[index.ravel()]


def units(rec: Recording, cell: np.ndarray) -> list[np.ndarray]:
    """Sample indices of each (episode, cell) run, in step order."""
    order = np.lexsort((rec.step, cell, rec.episode))
    key = rec.episode[order] * (int(cell.max()) + 1 if cell.size else 1) + cell[order]
    edges = np.flatnonzero(np.diff(key)) + 1
    return np.split(order, edges) if order.size else []


def block_length(rec: Recording, channels) -> int:
    """The project's one block-length rule (``gap.blocklength``) over the residuals of
    each run; at least 5 samples (a block carries spreads and lagged products), at
    most half the longest run."""
    labels, cell = cells(rec)
    runs = [r for r in units(rec, cell) if r.size >= 2]
    if not runs:
        return 5
    x = rec.readings[:, list(channels)].astype(np.float64)
    y = np.concatenate([x[r] - x[r].mean(axis=0) for r in runs])
    edges = np.cumsum([0] + [r.size for r in runs])
    segments = [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]
    longest = max(r.size for r in runs)
    return blocklength.block_length(y, segments, minimum=5, maximum=max(5, longest // 2))


_LAYOUTS: OrderedDict = OrderedDict()
LAYOUT_CACHE = 32


def _layout(rec: Recording, length: int) -> dict:
    """How samples fall into cells, runs and blocks: the same for every replay of a
    protocol (``gap.replay`` reuses the index columns of a replay), so it is cached by
    the identity of those columns (references are held, so identities stay unique)."""
    cols = (rec.episode, rec.step, rec.heading_deg, rec.condition)
    key = tuple(id(c) for c in cols) + (length,)
    hit = _LAYOUTS.get(key)
    if hit is not None:
        _LAYOUTS.move_to_end(key)
        return hit[1]
    labels, cell = cells(rec)
    runs = units(rec, cell)
    order = np.concatenate(runs)
    run_sizes = np.array([r.size for r in runs], np.int64)
    run_at = (order, np.r_[0, np.cumsum(run_sizes)[:-1]], run_sizes)
    run_of = np.repeat(np.arange(len(runs)), [r.size for r in runs])
    position = np.concatenate([np.arange(r.size) for r in runs])
    block_key = run_of * (position.max() // length + 2) + position // length
    _, block = np.unique(block_key, return_inverse=True)
    sizes = np.bincount(block)
    keep = sizes[block] >= 2                     # a lone sample carries no spread
    order, block, run_of = order[keep], block[keep], run_of[keep]
    _, block = np.unique(block, return_inverse=True)
    nb = int(block.max()) + 1 if block.size else 0
    block_of = np.full(len(rec), -1)
    block_of[order] = block
    stratum = np.zeros(nb, np.int64)
    stratum[block] = cell[order]
    out = {'labels': labels, 'cell': cell, 'runs': runs, 'run_at': run_at,
           'order': order, 'block': block,
           'nb': nb, 'block_of': block_of, 'stratum': stratum,
           'lags': _lag_pairs(rec.step[order], run_of)}
    _LAYOUTS[key] = (cols, out)
    if len(_LAYOUTS) > LAYOUT_CACHE:
        _LAYOUTS.popitem(last=False)
    return out


def stationary_blocks(rec: Recording, channels, length: int,
                      column_major: bool = False) -> Blocks:
    """Sufficient sums of stationary data in blocks of ``length`` consecutive samples;
    ``column_major``: the table stored column by column where it is made directly (for
    the full data's sums alone, ``blocksums.Packer``): the same numbers."""
    channels = tuple(channels)
    lay = _layout(rec, length)
    labels = lay['labels']
    order, nb = lay['order'], lay['nb']
    if 'segments' not in lay:
        lay['segments'] = _segments(lay['block'], nb)
    block = lay['segments']
    x, dropped = dropout.columns(rec, channels)     # dropouts counted on their own
    # residuals about each run's own mean: the same small bias for real and simulated
    # runs alike (runs partition the samples; sums in sample order, as ``mean`` adds)
    run_order, run_starts, run_sizes = lay['run_at']
    if 'runs_sorted' not in lay:     # samples already in run order (a replay's are)
        lay['runs_sorted'] = bool(np.array_equal(run_order, np.arange(len(rec))))
    if lay['runs_sorted']:
        run_means = np.add.reduceat(x, run_starts, axis=0) / run_sizes[:, None]
        y = x - np.repeat(run_means, run_sizes, axis=0)
    else:
        run_means = np.add.reduceat(x[run_order], run_starts, axis=0) / run_sizes[:, None]
        y = np.empty_like(x)
        y[run_order] = x[run_order] - np.repeat(run_means, run_sizes, axis=0)
    if 'sorted' not in lay:     # samples already in block order (a replay's are)
        lay['sorted'] = bool(order.size == len(rec) and
                             np.array_equal(order, np.arange(order.size)))

    def inorder(a: np.ndarray) -> np.ndarray:
        return a if lay['sorted'] else a[order]
    yo, xo = inorder(y), inorder(x)
    if 'by_stratum' not in lay:       # blocks in stratum order, as ``Blocks`` keeps them
        lay['by_stratum'] = np.argsort(lay['stratum'], kind='stable')
    if 'largest' not in lay:
        lay['largest'] = int(np.bincount(lay['block']).max()) if nb else 0
    if 'direct' not in lay:      # blocks short enough to be added straight into the table
        lay['direct'] = 0 < lay['largest'] <= blocksums.SEQUENTIAL
    cut = _cut(lay) if lay['direct'] else block
    sums = blocksums.Packer(_shapes(len(channels)), nb, lay['by_stratum'],
                            lay['rows'] if lay['direct'] else None, column_major)
    # products in single precision (sums over a block of at most a few hundred samples
    # keep 6 digits), levels and first moments in double
    y32 = yo.astype(np.float32)
    rows = blocksums.taken(y32)
    sums.put('n', np.bincount(lay['block'], minlength=nb)[:, None].astype(np.float64))
    sums.add('sx', cut, blocksums.taken(xo))
    sums.add('s1', cut, blocksums.taken(yo))
    # cross products: the upper triangle only (``_cross`` fills in the rest after summing)
    sums.add('s2', cut, lambda at: blockcounts.upper_products(y32) if at is None
             else blockcounts.upper_of(rows(at)))
    sums.add('s4', cut, lambda at: np.square(np.square(rows(at))))
    _lagged(lay, y32, nb, sums)
    own = inorder(ownpart.residuals(y, lay))
    own_rows = blocksums.taken(own)
    sums.add('own_s2', cut, lambda at: np.square(own_rows(at)))
    _lagged(lay, own, nb, sums, 'own_lag_s')
    integer = bool(np.all(x == np.round(x)))
    if integer:
        cells = (len(lay['labels']), lay['cell'], inorder(lay['cell']))
        blockcounts.count(x, xo, inorder, cells, MODULI, sums, cut, lay['largest'])
    else:
        # at_mode and residue: not counted, zeros
        sums.add('edge', cut, blocksums.taken(inorder(pileup.edge_hits(x))))
    # no dropout marks (most replays): their block sums are zeros, no need to add them
    if dropped.any():
        sums.add('dropped', cut, blocksums.taken(inorder(dropped)))
    else:
        sums.put_at('dropped', np.zeros(0, np.int64), np.zeros(0))
    _transitions(rec, lay, x, run_means, sums)
    table, layout = sums.done(_block_sum, pack)
    # counts from 'n' on, then parts zero in all but a few blocks (``resample._picked``)
    return Blocks('stationary', channels, labels, lay['stratum'][lay['by_stratum']], table,
                  layout, {'integer': integer, 'counts': layout['n'][0].start,
                           'rare': layout['dropped'][0].start})


def _shapes(c: int) -> dict:
    """The parts of the stationary block sums and their per-block shapes, in table order:
    sums of readings, then counts (whole numbers, from 'n'), then the parts that are zero
    in all but a few blocks (from 'dropped'; ``resample._picked`` uses the order)."""
    return {'sx': (c,), 's1': (c,), 's2': (c * (c + 1) // 2,), 's4': (c,),
            'lag_s': (len(LAGS), c), 'own_s2': (c,), 'own_lag_s': (len(LAGS), c),
            'n': (1,), 'lag_n': (len(LAGS),), 'at_mode': (c,),
            'residue': (c, len(MODULI)), 'edge': (c, 2), 'dropped': (c, 2),
            'step_dd': (STEP_LAGS, c), 'step_d2': (STEP_LAGS, c)}


def _cut(lay: dict) -> blocksums.Segments:
    """The blocks as ``blocksums.Segments`` of the samples in block order, each summed
    into its row of the stratum-ordered table (once per protocol)."""
    if 'cut' not in lay:
        lay['rows'] = np.empty(lay['nb'], np.int64)
        lay['rows'][lay['by_stratum']] = np.arange(lay['nb'])
        starts, targets, _ = lay['segments']
        lay['cut'] = blocksums.Segments(starts, targets, lay['order'].size, lay['rows'])
    return lay['cut']


def _transitions(rec: Recording, lay: dict, x: np.ndarray, run_means: np.ndarray,
                 sums: blocksums.Packer) -> None:
    """Step responses where a run follows another in the same episode without a gap.

    For the j-th sample after the change, d = x - (new run's mean) against the change
    D = (old mean) - (new mean): sums of d * D and D^2 per channel, credited to the
    block of the new run's first sample (parts ``step_dd``, ``step_d2``).  d / D is 0
    for a sensor that follows the change at once and 1 while it still reports the old
    heading.
    """
    if 'changes' not in lay:
        lay['changes'] = _changes(rec, lay['runs'], lay['block_of'])
    at, samples, old, new = lay['changes']
    dd = d2 = np.zeros((0, STEP_LAGS, x.shape[1]))
    if at.size:      # each change has a block of its own
        change = run_means[old] - run_means[new]
        dd = (x[samples] - run_means[new][:, None, :]) * change[:, None, :]
        d2 = np.broadcast_to((change ** 2)[:, None, :], dd.shape)
    sums.put_at('step_dd', at, dd)
    sums.put_at('step_d2', at, d2)


def _changes(rec: Recording, runs: list[np.ndarray], block_of: np.ndarray) -> tuple:
    """(block, first ``STEP_LAGS`` samples, old run, new run) of every change of heading
    that ``_transitions`` times: the same for every replay of a protocol."""
    by_start = sorted(range(len(runs)),
                      key=lambda i: (int(rec.episode[runs[i][0]]), int(rec.step[runs[i][0]])))
    out = []
    for i, j in zip(by_start[:-1], by_start[1:]):
        old, new = runs[i], runs[j]
        b = block_of[new[0]]
        if rec.episode[old[0]] != rec.episode[new[0]] or b < 0 or \
                rec.step[new[0]] != rec.step[old[-1]] + 1 or new.size <= STEP_LAGS:
            continue
        out.append((b, new[:STEP_LAGS], i, j))
    if not out:
        return (np.zeros(0, np.int64),) * 4
    at, samples, old, new = zip(*out)
    return np.array(at), np.array(samples), np.array(old), np.array(new)


def _block_sum(block, values: np.ndarray, blocks: int) -> np.ndarray:
    """Sums of ``values`` per block (in their own precision), as doubles; ``block`` must be
    non-decreasing (or its ``_segments``)."""
    starts, targets, dense = _segments(block, blocks) if isinstance(block, np.ndarray) \
        else block
    if dense:                   # every block has samples, in order: no scatter needed
        return np.add.reduceat(values, starts, axis=0).astype(np.float64)
    out = np.zeros((blocks,) + values.shape[1:])
    if starts.size:
        out[targets] = np.add.reduceat(values, starts, axis=0)
    return out


def _segments(block: np.ndarray, blocks: int) -> tuple:
    """(first position of each block's run in ``block``, its block, whether those are
    0..blocks-1 in order): how ``_block_sum`` cuts values, the same for every replay."""
    if not block.size:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), False
    starts = np.flatnonzero(np.r_[True, np.diff(block) != 0])
    targets = block[starts]
    return starts, targets, bool(targets.size == blocks and
                                 np.array_equal(targets, np.arange(blocks)))


def _lag_pairs(steps: np.ndarray, run: np.ndarray) -> list:
    """Per lag, (hit, partner): samples with a partner ``lag`` steps later in their run."""
    key = run.astype(np.int64) * (int(steps.max()) + max(LAGS) + 2) + steps
    sorter = np.argsort(key)
    out = []
    for lag in LAGS:
        at = np.minimum(np.searchsorted(key, key + lag, sorter=sorter), key.size - 1)
        partner = sorter[at]
        hit = key[partner] == key + lag
        out.append((hit, partner[hit]))
    return out


def _lagged(lay: dict, y: np.ndarray, blocks: int, sums: blocksums.Packer,
            part: str = 'lag_s') -> None:
    """Products of residues ``lag`` steps apart in the same run, credited to the block of
    the first sample: (blocks, lags, C) sums ``part`` and, of ``lag_s``, (blocks, lags)
    counts ``lag_n``."""
    if 'lag_segments' not in lay:       # the same for every replay of the protocol
        lay['lag_segments'] = [(np.bincount(lay['block'][hit], minlength=blocks),
                                _segments(lay['block'][hit], blocks))
                               for hit, _ in lay['lags']]
    if 'lag_shifts' not in lay:     # each partner ``lag`` rows on: products of shifted rows
        lay['lag_shifts'] = [_shifted(lay, hit, partner, lag)
                             for lag, (hit, partner) in zip(LAGS, lay['lags'])]
    if part == 'lag_s':
        sums.put('lag_n', np.stack([count for count, _ in lay['lag_segments']], axis=1)
                 .astype(np.float64))
    for li, ((hit, partner), (_, segments), shift) in enumerate(zip(
            lay['lags'], lay['lag_segments'], lay['lag_shifts'])):
        if shift is None:
            pairs = np.flatnonzero(hit)

            def product(at, pairs=pairs, partner=partner, hit=hit):
                if at is None:
                    return y[hit] * y[partner]
                return np.take(y, pairs[at], axis=0) * np.take(y, partner[at], axis=0)
            cut = segments
            if sums.direct:
                cut = _lag_cut(lay, li, segments, pairs.size)
        else:       # the same products, zeros between them: the same sums (x + 0 is x)
            lag, kept, cut = shift
            ahead = np.r_[kept, np.zeros(lag, bool)]

            def product(at, lag=lag, kept=kept, ahead=ahead):
                if at is None:
                    out = np.zeros_like(y)
                    np.multiply(y[:-lag], y[lag:], out=out[:-lag], where=kept[:, None])
                    return out
                out = np.take(y, at, axis=0) * np.take(y, np.minimum(at + lag, len(y) - 1),
                                                       axis=0)
                out[~ahead[at]] = 0.0
                return out
            if sums.direct:
                cut = _cut(lay)
        sums.add(part, cut, product, li)


def _lag_cut(lay: dict, li: int, segments: tuple, n: int) -> blocksums.Segments:
    """``_cut`` of the samples with a partner at lag number ``li`` (once per protocol)."""
    cuts = lay.setdefault('lag_cuts', {})
    if li not in cuts:
        _cut(lay)
        cuts[li] = blocksums.Segments(segments[0], segments[1], n, lay['rows'])
    return cuts[li]


SEQUENTIAL = 8    # numpy adds a block of at most this many rows one by one, in order


def _shifted(lay: dict, hit: np.ndarray, partner: np.ndarray, lag: int):
    """(lag, which of the first N - lag rows have their partner, the blocks' segments)
    when every partner lies ``lag`` rows after its sample, else None; then a row's
    product can be made in place, unmoved.  Only for blocks numpy sums one row after
    another (at most ``SEQUENTIAL`` rows; longer ones it sums pairwise, eight at a time,
    and the zeros between the products would move the pairs)."""
    n = hit.size
    at = np.flatnonzero(hit)
    largest = int(np.bincount(lay['block']).max()) if lay['block'].size else 0
    if largest > SEQUENTIAL or n <= lag or not np.array_equal(partner, at + lag) \
            or hit[n - lag:].any():
        return None
    return lag, hit[:n - lag].copy(), lay['segments']


def closed_loop_blocks(rec: Recording, perturb_every: int, loop_only: bool = False) -> Blocks:
    """Per-episode sums of closed-loop Khepera data (``gap.closedloop``)."""
    return _closed_loop_blocks(rec, perturb_every, loop_only)


def compute(blocks: Blocks, replicates: int = REPLICATES, seed: int = 0) -> Stats:
    """All statistics of ``blocks``, full data first, then ``replicates`` resamples."""
    sums = resampled(blocks, replicates, seed)
    with np.errstate(invalid='ignore', divide='ignore'):
        if blocks.kind == 'stationary':
            return _stationary_stats(blocks, sums)
        return closed_loop_stats(blocks, sums)


def _stationary_stats(b: Blocks, sums: np.ndarray) -> Stats:
    n = b.part(sums, 'n')[..., 0]                            # (R, S)
    s1, s2 = b.part(sums, 's1'), _cross(b.part(sums, 's2'), len(b.channels))
    level = b.part(sums, 'sx') / n[..., None]                 # (R, S, C)
    centred = s2 - s1[..., :, None] * s1[..., None, :] / n[..., None, None]
    cell_var = np.diagonal(centred, axis1=-2, axis2=-1) / (n[..., None] - 1)
    conditions = list(dict.fromkeys(c for c, _ in b.strata))
    ch = b.channels
    r = sums.shape[0]
    # columns in the order of ``_stationary_keys``
    cell_sd = np.sqrt(cell_var)
    cols = [np.stack([level, cell_sd], axis=3).reshape(r, -1)]
    pairs = np.triu_indices(len(ch), 1)
    members = {c: [s for s, lab in enumerate(b.strata) if lab[0] == c] for c in conditions}
    for c in conditions:
        m = members[c]
        dof = (n[:, m] - 1).sum(axis=1)
        cov = centred[:, m].sum(axis=1) / dof[:, None, None]
        var = np.diagonal(cov, axis1=-2, axis2=-1)
        sd = np.sqrt(var)
        corr = cov / (sd[:, :, None] * sd[:, None, :])
        lag_n = b.part(sums, 'lag_n')[:, m].sum(axis=1)          # (R, L)
        lag_s = b.part(sums, 'lag_s')[:, m].sum(axis=1)          # (R, L, C)
        acf = lag_s / lag_n[..., None] / var[:, None, :]
        s4 = b.part(sums, 's4')[:, m].sum(axis=1)
        total = n[:, m].sum(axis=1)
        kurt = s4 / total[:, None] / var ** 2 - 3.0
        cols += [corr[:, pairs[0], pairs[1]], acf.reshape(r, -1), kurt]
        if len(ch) >= ownpart.MIN_CHANNELS:
            own = ownpart.autocorrelation(b.part(sums, 'own_lag_s')[:, m].sum(axis=1),
                                          b.part(sums, 'own_s2')[:, m].sum(axis=1))
            cols.append(own.reshape(r, -1))
    cols.append(_slopes(level, cell_sd))
    d2 = b.part(sums, 'step_d2').sum(axis=1)                       # (R, J, C)
    timed = None
    if (d2[0] > 0).any():
        response = b.part(sums, 'step_dd').sum(axis=1) / d2
        # changes too small to time are left out
        timed = tuple(bool(v) for v in d2[0, 0] >= 100.0 * STEP_LAGS)
        cols.append(response[:, :, list(timed)].transpose(0, 2, 1).reshape(r, -1))
    total = n.sum(axis=1)[:, None]
    edge = b.part(sums, 'edge').sum(axis=1) / total[..., None]           # (R, C, 2)
    cols.append(edge.reshape(r, -1))
    dropped = b.part(sums, 'dropped').sum(axis=1) / total[..., None]     # (R, C, 2)
    cols.append(np.stack([v for _, v in dropout.shares('dropout', ch, None, dropped)], axis=1))
    if b.extra['integer']:
        for c in conditions:
            m = members[c]
            cols.append(b.part(sums, 'at_mode')[:, m].sum(axis=1)
                        / n[:, m].sum(axis=1)[:, None])
        frac = b.part(sums, 'residue').sum(axis=1) / total[..., None]
        cols.append(frac.reshape(r, -1))
    keys = _stationary_keys(tuple(b.strata), tuple(ch), timed, bool(b.extra['integer']))
    return Stats(keys, np.concatenate(cols, axis=1))


def _cross(upper: np.ndarray, channels: int) -> np.ndarray:
    """(..., C, C) symmetric sums of cross products from their upper triangle (..., C (C +
    1) / 2) in ``np.triu_indices`` order: each sum below the diagonal is the same sum of
    the same products as its mirror above, so copying it is exact."""
    out = np.zeros(upper.shape[:-1] + (channels, channels))
    i, j = np.triu_indices(channels)
    out[..., i, j] = upper
    out[..., j, i] = upper
    return out


@functools.lru_cache(maxsize=64)
def _stationary_keys(strata: tuple, ch: tuple, timed: tuple | None, integer: bool) -> list:
    """The keys of ``_stationary_stats``, in its column order: the same for every
    simulation of one protocol, so built once (a shared list: never modify it)."""
    conditions = list(dict.fromkeys(c for c, _ in strata))
    keys = []
    for c, h in strata:
        part = None if h is None else f'heading {h:g} deg'
        for sensor in ch:
            keys += [Key('level', (sensor,), c, part), Key('spread', (sensor,), c, part)]
    for c in conditions:
        keys += [Key('correlation', (ch[k], ch[m]), c, None)
                 for k in range(len(ch)) for m in range(k + 1, len(ch))]
        keys += [Key('autocorrelation', (sensor,), c, f'lag {lag}')
                 for lag in LAGS for sensor in ch]
        keys += [Key('kurtosis', (sensor,), c, None) for sensor in ch]
        if len(ch) >= ownpart.MIN_CHANNELS:
            keys += [Key('own_autocorrelation', (sensor,), c, f'lag {lag}')
                     for lag in LAGS for sensor in ch]
    keys += [Key('spread_vs_level', (sensor,), None, None) for sensor in ch]
    if timed is not None:
        keys += [Key('step_response', (sensor,), None, f'sample {j} after a change')
                 for sensor, ok in zip(ch, timed) if ok for j in range(STEP_LAGS)]
    keys += [Key('pileup', (sensor,), None, end) for sensor in ch for end in pileup.ENDS]
    keys += [k for k, _ in dropout.shares('dropout', ch, None, np.zeros((1, len(ch), 2)))]
    if integer:
        keys += [Key('mode_share', (sensor,), c, None) for c in conditions for sensor in ch]
        keys += [Key('granularity', (sensor,), None, f'step {q}') for sensor in ch
                 for q in MODULI]
    return keys


def _slopes(level: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """(R, C) least-squares slope of per-cell spread on per-cell level, per channel."""
    dl = level - level.mean(axis=1, keepdims=True)
    ds = sd - sd.mean(axis=1, keepdims=True)
    return (dl * ds).sum(axis=1) / (dl * dl).sum(axis=1)
