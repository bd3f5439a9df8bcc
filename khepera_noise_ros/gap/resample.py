"""Block-bootstrap resampling of block sums: stratified draws of blocks, and each stratum's
weighted sums for the full data and every replicate (``gap.statistics``)."""
from __future__ import annotations

import functools
from collections import OrderedDict

import numpy as np
from scipy import sparse

from .blocks import Blocks


def weights(blocks: Blocks, replicates: int, rng: np.random.Generator) -> np.ndarray:
    """(1 + R, B) block weights: the full data, then stratified bootstrap draws."""
    b = blocks.stratum.size
    codes = []
    for lo, hi in zip(blocks.edges[:-1], blocks.edges[1:]):
        if replicates and hi > lo:
            picks = rng.integers(lo, hi, size=(replicates, hi - lo))
            codes.append((np.arange(1, replicates + 1)[:, None] * b + picks).ravel())
    w = np.bincount(np.concatenate(codes), minlength=(1 + replicates) * b) if codes else \
        np.zeros((1 + replicates) * b)
    w = w.reshape(1 + replicates, b).astype(np.float64)
    w[0] = 1.0
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
    # Blocks are sorted by stratum.  Rows of the selection matrix are (stratum, replicate),
    # each holding that stratum's blocks in order, so a stratum's sums stay in cache while
    # its replicates are added up (the same products, added in the same order, as with
    # rows by replicate); built directly in CSR form.  Blocks a replicate did not draw
    # (weight 0, a third of them) are left out: adding 0 x a finite sum changes nothing,
    # so only when every sum is finite.
    finite = bool(np.isfinite(blocks.sums.sum()))
    return _picked(_selection(blocks.edges, w, finite), blocks, r, finite)


def _selection(edges: np.ndarray, w: np.ndarray, finite: bool):
    """The (strata x R, B) CSR selection matrix of weights ``w`` (see ``stratum_sums``);
    ``finite``: every block sum is finite (a finite total), so undrawn blocks may go."""
    r, b = w.shape
    strata = edges.size - 1
    flat, col, rows = _stratum_major(tuple(edges.tolist()), r)
    data = np.take(w.ravel(), flat)
    if finite:
        drawn = data != 0.0
        data, col, rows = data[drawn], col[drawn], rows[drawn]
    indptr = np.r_[0, np.cumsum(np.bincount(rows, minlength=r * strata))]
    return sparse.csr_matrix((data, col, indptr), shape=(r * strata, b))


def _picked(pick, blocks: Blocks, r: int, finite: bool) -> np.ndarray:
    """(R, S, D) sums of the blocks ``pick`` selects (its rows: stratum by replicate).

    The sum of each column is its own (the product adds each column's terms in the same
    order, whatever the other columns), so parts may be summed apart.  Counts (the
    columns from ``blocks.extra['counts']`` to ``'rare'``: whole numbers, as are the
    weights) are exact in any order: a dense product per stratum.  The columns from
    ``'rare'`` on, parts that are zero in all but a few blocks (dropouts, step
    responses), are summed over the blocks where they are not zero: the terms left out
    are zeros (a finite weight times 0), and adding a zero changes no sum (never -0:
    sums start at +0).  Only when every sum is finite (else 0 x inf would be NaN)."""
    rare = blocks.extra.get('rare') if finite else None
    if rare is None:
        out = np.asarray(pick @ blocks.sums)
    else:
        counts = blocks.extra.get('counts', rare)
        out = np.empty((pick.shape[0], blocks.sums.shape[1]))
        out[:, :counts] = pick @ np.ascontiguousarray(blocks.sums[:, :counts])
        if counts < rare:
            out[:, counts:rare] = _whole(pick, blocks, r, counts, rare)
        tail = blocks.sums[:, rare:]
        rows = np.flatnonzero(tail.any(axis=1))
        out[:, rare:] = (pick[:, rows] @ tail[rows]) if rows.size else 0.0
    out = out.reshape(len(blocks.strata), r, -1)
    return np.ascontiguousarray(out.transpose(1, 0, 2))


_DENSE: OrderedDict = OrderedDict()


def _whole(pick, blocks: Blocks, r: int, a: int, b: int) -> np.ndarray:
    """``pick @ blocks.sums[:, a:b]`` for columns of whole numbers: each stratum's dense
    weights (R, its blocks), made once per selection matrix, times its blocks."""
    hit = _DENSE.get(id(pick))
    if hit is None or hit[0] is not pick:
        edges = blocks.edges
        dense = [pick[s * r:(s + 1) * r, lo:hi].toarray()
                 for s, (lo, hi) in enumerate(zip(edges[:-1], edges[1:]))]
        hit = _DENSE[id(pick)] = (pick, dense)
        if len(_DENSE) > PICK_CACHE:
            _DENSE.popitem(last=False)
    x = blocks.sums[:, a:b]
    out = np.empty((pick.shape[0], b - a))
    for s, (lo, hi) in enumerate(zip(blocks.edges[:-1], blocks.edges[1:])):
        out[s * r:(s + 1) * r] = hit[1][s] @ x[lo:hi]
    return out


_PICKS: OrderedDict = OrderedDict()
PICK_CACHE = 8


def resampled(blocks: Blocks, replicates: int, seed: int) -> np.ndarray:
    """``stratum_sums`` of ``weights`` drawn with ``seed``.  The draws depend on the strata's
    block counts, ``replicates`` and ``seed`` alone, which every simulation a target
    compares shares: the selection matrix is built once for them (the same matrix)."""
    if not replicates:
        return stratum_sums(blocks, weights(blocks, 0, np.random.default_rng(seed)))
    finite = bool(np.isfinite(blocks.sums.sum()))
    key = (tuple(blocks.edges.tolist()), replicates, seed, finite)
    pick = _PICKS.get(key)
    if pick is None:
        w = weights(blocks, replicates, np.random.default_rng(seed))
        pick = _PICKS[key] = _selection(blocks.edges, w, finite)
        if len(_PICKS) > PICK_CACHE:
            _PICKS.popitem(last=False)
    else:
        _PICKS.move_to_end(key)
    return _picked(pick, blocks, 1 + replicates, finite)


@functools.lru_cache(maxsize=8)
def _stratum_major(edges: tuple, r: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(position in the (r, B) weights, block, row) of every weight, stratum by stratum,
    replicate by replicate (the row is stratum x r + replicate)."""
    b = edges[-1]
    flat, col, rows = [], [], []
    for s, (lo, hi) in enumerate(zip(edges[:-1], edges[1:])):
        rep = np.repeat(np.arange(r), hi - lo)
        col.append(np.tile(np.arange(lo, hi), r))
        flat.append(rep * b + col[-1])
        rows.append(s * r + rep)
    return np.concatenate(flat), np.concatenate(col), np.concatenate(rows)
