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

from collections import OrderedDict

import numpy as np
from scipy import sparse

from ..recording import Recording
from . import blocklength, dropout, pileup
from .blocks import FACTORS, Blocks, Key, Stats, pack  # noqa: F401 (FACTORS, Key re-exported)
from .closedloop import closed_loop_blocks as _closed_loop_blocks, closed_loop_stats

LAGS = (1, 3)                    # autocorrelation lags, in steps
MODULI = (2, 3, 4, 5, 8, 10)     # quantisation steps tested by the granularity family
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


def stationary_blocks(rec: Recording, channels, length: int) -> Blocks:
    """Sufficient sums of stationary data in blocks of ``length`` consecutive samples."""
    channels = tuple(channels)
    lay = _layout(rec, length)
    labels, cell, runs = lay['labels'], lay['cell'], lay['runs']
    order, block, nb = lay['order'], lay['block'], lay['nb']
    x, dropped = dropout.columns(rec, channels)     # dropouts counted on their own
    # residuals about each run's own mean: the same small bias for real and simulated
    # runs alike (runs partition the samples; sums in sample order, as ``mean`` adds)
    run_order, run_starts, run_sizes = lay['run_at']
    run_means = np.add.reduceat(x[run_order], run_starts, axis=0) / run_sizes[:, None]
    y = np.empty_like(x)
    y[run_order] = x[run_order] - np.repeat(run_means, run_sizes, axis=0)
    yo, xo = y[order], x[order]
    # products in single precision (sums over a block of at most a few hundred samples
    # keep 6 digits), levels and first moments in double
    y32 = yo.astype(np.float32)
    upper = np.triu_indices(len(channels))
    s2 = np.zeros((nb, len(channels), len(channels)))
    s2[:, upper[0], upper[1]] = _block_sum(block, y32[:, upper[0]] * y32[:, upper[1]], nb)
    s2 = s2 + np.triu(s2, 1).transpose(0, 2, 1)         # symmetric: half the products
    parts = {'n': np.bincount(block, minlength=nb)[:, None].astype(np.float64),
             'sx': _block_sum(block, xo, nb),
             's1': _block_sum(block, yo, nb),
             's2': s2,
             's4': _block_sum(block, np.square(np.square(y32)), nb)}
    parts['lag_n'], parts['lag_s'] = _lagged(lay['lags'], y32, block, nb)
    integer = bool(np.all(x == np.round(x)))
    modes = _cell_modes(x, cell, len(labels)) if integer else np.full((len(labels), x.shape[1]),
                                                                      np.nan)
    parts['at_mode'] = _block_sum(block, (xo == modes[cell[order]]).astype(np.float32), nb)
    residues = _residues(x) if integer else None      # one table serves both uses
    residue = (residues[order] == _modal_residues(x, residues)[None]).astype(np.float32) \
        if integer else np.zeros((xo.shape[0], len(channels), len(MODULI)))
    parts['residue'] = _block_sum(block, residue, nb)
    parts['edge'] = _block_sum(block, pileup.edge_hits(x)[order], nb)
    parts['dropped'] = _block_sum(block, dropped[order], nb)
    parts['step_dd'], parts['step_d2'] = _transitions(rec, runs, x, lay['block_of'], nb,
                                                      run_means)
    sums, layout = pack(parts, nb)
    return Blocks('stationary', channels, labels, lay['stratum'], sums, layout,
                  {'integer': integer})


def _transitions(rec: Recording, runs: list[np.ndarray], x: np.ndarray, block_of: np.ndarray,
                 blocks: int, run_means: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Step responses where a run follows another in the same episode without a gap.

    For the j-th sample after the change, d = x - (new run's mean) against the change
    D = (old mean) - (new mean): sums of d * D and D^2 per channel, credited to the
    block of the new run's first sample.  d / D is 0 for a sensor that follows the
    change at once and 1 while it still reports the old heading.
    """
    dd = np.zeros((blocks, STEP_LAGS, x.shape[1]))
    d2 = np.zeros((blocks, STEP_LAGS, x.shape[1]))
    by_start = sorted(range(len(runs)),
                      key=lambda i: (int(rec.episode[runs[i][0]]), int(rec.step[runs[i][0]])))
    starts = [runs[i] for i in by_start]
    means = run_means[by_start]
    for i, (old, new) in enumerate(zip(starts[:-1], starts[1:])):
        b = block_of[new[0]]
        if rec.episode[old[0]] != rec.episode[new[0]] or b < 0 or \
                rec.step[new[0]] != rec.step[old[-1]] + 1 or new.size <= STEP_LAGS:
            continue
        change = means[i] - means[i + 1]
        dd[b] += (x[new[:STEP_LAGS]] - means[i + 1]) * change
        d2[b] += change ** 2
    return dd, d2


def _block_sum(block: np.ndarray, values: np.ndarray, blocks: int) -> np.ndarray:
    """Sums of ``values`` per block (in their own precision), as doubles; ``block`` must be
    non-decreasing."""
    out = np.zeros((blocks,) + values.shape[1:])
    if block.size:
        starts = np.flatnonzero(np.r_[True, np.diff(block) != 0])
        out[block[starts]] = np.add.reduceat(values, starts, axis=0)
    return out


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


def _lagged(pairs: list, y: np.ndarray, block: np.ndarray,
            blocks: int) -> tuple[np.ndarray, np.ndarray]:
    """Products of residues ``lag`` steps apart in the same run, credited to the block of
    the first sample: (blocks, lags) counts and (blocks, lags, C) sums."""
    counts = np.zeros((blocks, len(LAGS)))
    sums = np.zeros((blocks, len(LAGS), y.shape[1]))
    for li, (hit, partner) in enumerate(pairs):
        counts[:, li] = np.bincount(block[hit], minlength=blocks)
        sums[:, li] = _block_sum(block[hit], y[hit] * y[partner], blocks)
    return counts, sums


def _cell_modes(x: np.ndarray, cell: np.ndarray, cells: int) -> np.ndarray:
    """(cells, C) the most common (integer) reading of each channel in each cell."""
    low = np.nanmin(x)
    span = int(np.nanmax(x) - low) + 1
    channels = x.shape[1]
    code = ((cell[:, None] * channels + np.arange(channels)[None, :]) * span
            + (x - low).astype(np.int64)).ravel()
    counts = np.bincount(code, minlength=cells * channels * span)
    return counts.reshape(cells, channels, span).argmax(axis=2) + low


def _residues(x: np.ndarray) -> np.ndarray:
    """(N, C, len(MODULI)) int16 residues of integer readings modulo each step (a table
    lookup: readings are small integers)."""
    low = int(np.nanmin(x)) if x.size else 0
    span = int(np.nanmax(x)) - low + 1 if x.size else 1
    table = np.mod(np.arange(low, low + span)[:, None], np.array(MODULI)[None, :])
    return table.astype(np.int16)[x.astype(np.int64) - low]


def _modal_residues(x: np.ndarray, residues: np.ndarray | None = None) -> np.ndarray:
    """(C, len(MODULI)) the most common residue of each channel modulo each step."""
    r = _residues(x) if residues is None else residues
    out = np.zeros((x.shape[1], len(MODULI)), np.int64)
    columns = np.arange(x.shape[1])
    for j, q in enumerate(MODULI):
        code = (r[:, :, j].astype(np.int64) + q * columns).ravel()
        out[:, j] = np.bincount(code, minlength=q * x.shape[1]).reshape(-1, q).argmax(axis=1)
    return out


def closed_loop_blocks(rec: Recording, perturb_every: int) -> Blocks:
    """Per-episode sums of closed-loop Khepera data (``gap.closedloop``)."""
    return _closed_loop_blocks(rec, perturb_every)


# -- resampling ---------------------------------------------------------------------------

def weights(blocks: Blocks, replicates: int, rng: np.random.Generator) -> np.ndarray:
    """(1 + R, B) block weights: the full data, then stratified bootstrap draws."""
    w = np.zeros((1 + replicates, blocks.stratum.size))
    w[0] = 1.0
    for lo, hi in zip(blocks.edges[:-1], blocks.edges[1:]):
        if replicates and hi > lo:
            picks = rng.integers(lo, hi, size=(replicates, hi - lo))
            rows = np.repeat(np.arange(1, replicates + 1), hi - lo)
            np.add.at(w, (rows, picks.ravel()), 1.0)
    return w


def stratum_sums(blocks: Blocks, w: np.ndarray) -> np.ndarray:
    """(R, S, D) weighted sums of each stratum's blocks."""
    r, b = w.shape
    strata = len(blocks.strata)
    if r == 1 and np.all(w == 1.0):       # the full data alone (fits): plain sums in block
        out = np.zeros((strata, blocks.sums.shape[1]))      # order, as the product adds
        lo = blocks.edges[:-1]
        used = blocks.edges[1:] > lo
        if used.any():
            out[used] += np.add.reduceat(blocks.sums, lo[used], axis=0)
        return out[None]
    rows = (np.arange(r)[:, None] * strata + blocks.stratum[None, :]).ravel()
    pick = sparse.csr_matrix((w.ravel(), (rows, np.tile(np.arange(b), r))),
                             shape=(r * strata, b))
    return np.asarray(pick @ blocks.sums).reshape(r, strata, -1)


def compute(blocks: Blocks, replicates: int = REPLICATES, seed: int = 0) -> Stats:
    """All statistics of ``blocks``, full data first, then ``replicates`` resamples."""
    w = weights(blocks, replicates, np.random.default_rng(seed))
    sums = stratum_sums(blocks, w)
    with np.errstate(invalid='ignore', divide='ignore'):
        if blocks.kind == 'stationary':
            return _stationary_stats(blocks, sums)
        return closed_loop_stats(blocks, sums)


def _stationary_stats(b: Blocks, sums: np.ndarray) -> Stats:
    n = b.part(sums, 'n')[..., 0]                            # (R, S)
    s1, s2 = b.part(sums, 's1'), b.part(sums, 's2')
    level = b.part(sums, 'sx') / n[..., None]                 # (R, S, C)
    centred = s2 - s1[..., :, None] * s1[..., None, :] / n[..., None, None]
    cell_var = np.diagonal(centred, axis1=-2, axis2=-1) / (n[..., None] - 1)
    conditions = list(dict.fromkeys(c for c, _ in b.strata))
    ch = b.channels
    keys, cols = [], []

    def add(key: Key, value: np.ndarray) -> None:
        keys.append(key)
        cols.append(value)

    cell_sd = np.sqrt(cell_var)
    for s, (c, h) in enumerate(b.strata):
        part = None if h is None else f'heading {h:g} deg'
        for k, sensor in enumerate(ch):
            add(Key('level', (sensor,), c, part), level[:, s, k])
            add(Key('spread', (sensor,), c, part), cell_sd[:, s, k])
    for c in conditions:
        members = [s for s, lab in enumerate(b.strata) if lab[0] == c]
        dof = (n[:, members] - 1).sum(axis=1)
        cov = centred[:, members].sum(axis=1) / dof[:, None, None]
        var = np.diagonal(cov, axis1=-2, axis2=-1)
        sd = np.sqrt(var)
        corr = cov / (sd[:, :, None] * sd[:, None, :])
        for k in range(len(ch)):
            for m in range(k + 1, len(ch)):
                add(Key('correlation', (ch[k], ch[m]), c, None), corr[:, k, m])
        lag_n = b.part(sums, 'lag_n')[:, members].sum(axis=1)          # (R, L)
        lag_s = b.part(sums, 'lag_s')[:, members].sum(axis=1)          # (R, L, C)
        acf = lag_s / lag_n[..., None] / var[:, None, :]
        for li, lag in enumerate(LAGS):
            for k, sensor in enumerate(ch):
                add(Key('autocorrelation', (sensor,), c, f'lag {lag}'), acf[:, li, k])
        s4 = b.part(sums, 's4')[:, members].sum(axis=1)
        total = n[:, members].sum(axis=1)
        kurt = s4 / total[:, None] / var ** 2 - 3.0
        for k, sensor in enumerate(ch):
            add(Key('kurtosis', (sensor,), c, None), kurt[:, k])
    slope = _slopes(level, cell_sd)
    for k, sensor in enumerate(ch):
        add(Key('spread_vs_level', (sensor,), None, None), slope[:, k])
    d2 = b.part(sums, 'step_d2').sum(axis=1)                       # (R, J, C)
    if (d2[0] > 0).any():
        response = b.part(sums, 'step_dd').sum(axis=1) / d2
        for k, sensor in enumerate(ch):
            if d2[0, 0, k] >= 100.0 * STEP_LAGS:     # changes too small to time are left out
                for j in range(STEP_LAGS):
                    add(Key('step_response', (sensor,), None, f'sample {j} after a change'),
                        response[:, j, k])
    total = n.sum(axis=1)[:, None]
    edge = b.part(sums, 'edge').sum(axis=1) / total[..., None]           # (R, C, 2)
    for k, sensor in enumerate(ch):
        for j, end in enumerate(pileup.ENDS):
            add(Key('pileup', (sensor,), None, end), edge[:, k, j])
    dropped = b.part(sums, 'dropped').sum(axis=1) / total[..., None]     # (R, C, 2)
    for key, value in dropout.shares('dropout', ch, None, dropped):
        add(key, value)
    if b.extra['integer']:
        for c in conditions:
            members = [s for s, lab in enumerate(b.strata) if lab[0] == c]
            share = b.part(sums, 'at_mode')[:, members].sum(axis=1) \
                / n[:, members].sum(axis=1)[:, None]
            for k, sensor in enumerate(ch):
                add(Key('mode_share', (sensor,), c, None), share[:, k])
        frac = b.part(sums, 'residue').sum(axis=1) / total[..., None]
        for k, sensor in enumerate(ch):
            for j, q in enumerate(MODULI):
                add(Key('granularity', (sensor,), None, f'step {q}'), frac[:, k, j])
    return Stats(keys, np.stack(cols, axis=1))


def _slopes(level: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """(R, C) least-squares slope of per-cell spread on per-cell level, per channel."""
    dl = level - level.mean(axis=1, keepdims=True)
    ds = sd - sd.mean(axis=1, keepdims=True)
    return (dl * ds).sum(axis=1) / (dl * dl).sum(axis=1)
