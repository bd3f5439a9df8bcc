"""Per-block counts and products of the stationary block sums (``gap.statistics``): the
upper-triangle products of residuals, each channel's modal reading and modal residues,
the pile ends, and the 0/1 indicators of a sample counted together, packed as digits
of one integer."""
from __future__ import annotations

import numpy as np

from . import blocksums, pileup


def upper_products(y: np.ndarray) -> np.ndarray:
    """(N, C (C + 1) / 2) products y_k y_m, k <= m, in ``np.triu_indices`` order."""
    c = y.shape[1]
    out = np.empty((y.shape[0], c * (c + 1) // 2), y.dtype)
    at = 0
    for k in range(c):
        np.multiply(y[:, k:k + 1], y[:, k:], out=out[:, at:at + c - k])
        at += c - k
    return out


DIGIT = 7     # bits per count when a block's 0/1 indicators are counted packed together


def upper_of(y: np.ndarray) -> np.ndarray:
    """``upper_products`` along the last axis of ``y`` (..., C): the same products."""
    i, j = np.triu_indices(y.shape[-1])
    return y[..., i] * y[..., j]


def counted(block: tuple, nb: int, on_mode: np.ndarray, table: np.ndarray, at: np.ndarray,
            edge: np.ndarray) -> dict:
    """Per block and channel, how many samples are at the cell's mode, on each modal
    residue and at each pile end: the nine 0/1 indicators of a sample packed as digits of
    ``DIGIT`` bits in one integer and summed at once (exact while every block has fewer
    than 2 ** ``DIGIT`` samples, the same counts as summing each indicator)."""
    q = table.shape[1]
    code = packed(on_mode, code_table(table), at)
    code += edge[..., 0].astype(np.int64) << (DIGIT * (1 + q))
    code += edge[..., 1].astype(np.int64) << (DIGIT * (2 + q))
    starts, targets, dense = block
    counts = np.zeros((nb, code.shape[1]), np.int64)
    if starts.size:
        counts[targets] = np.add.reduceat(code, starts, axis=0)
    return digits(counts, q)


def code_table(table: np.ndarray, edge: np.ndarray | None = None) -> np.ndarray:
    """(V,) int64 digits of the modal residues (``table``: (V, Q) 0/1) and, if given, of
    the pile ends (``edge``: (V, 2) 0/1) of each of V (reading, channel) entries."""
    q = table.shape[1]
    shifts = DIGIT * np.arange(1, q + 3, dtype=np.int64)
    out = (table.astype(np.int64) << shifts[:q]).sum(axis=1)
    if edge is not None:
        out += (edge.astype(np.int64) << shifts[q:]).sum(axis=1)
    return out


def packed(on_mode: np.ndarray, codes: np.ndarray, at: np.ndarray) -> np.ndarray:
    """(N, C) int64, a sample's indicators as digits: at the mode, then ``codes[at]``
    (``code_table``'s; ``at``: each reading's entry)."""
    return on_mode.astype(np.int64) + np.take(codes, at)


def digits(counts: np.ndarray, q: int, out: dict | None = None) -> dict:
    """{'at_mode' (n, C), 'residue' (n, C, q), 'edge' (n, C, 2)} float64 counts from
    packed ``counts`` (n, C); ``out``: arrays of those shapes to write them into."""
    mask = (1 << DIGIT) - 1
    if out is None:
        n, c = counts.shape
        out = {'at_mode': np.empty((n, c)), 'residue': np.empty((n, c, q)),
               'edge': np.empty((n, c, 2))}
    out['at_mode'][...] = counts & mask
    for j in range(q):
        out['residue'][..., j] = (counts >> (DIGIT * (1 + j))) & mask
    for end in (0, 1):
        out['edge'][..., end] = (counts >> (DIGIT * (1 + q + end))) & mask
    return out


def cell_counts(xi: np.ndarray, cell: np.ndarray, cells: int, span: int) -> np.ndarray:
    """(cells, C, span) how often each channel reads each value in each cell (``xi``:
    integer readings less their least, all below ``span``)."""
    channels = xi.shape[1]
    code = ((cell[:, None] * channels + np.arange(channels)[None, :]) * span + xi).ravel()
    return np.bincount(code, minlength=cells * channels * span).reshape(cells, channels, span)


def cell_modes(xi: np.ndarray, cell: np.ndarray, cells: int, span: int) -> np.ndarray:
    """(cells, C) the most common reading of each channel in each cell (``xi``: integer
    readings less their least, all below ``span``)."""
    return cell_counts(xi, cell, cells, span).argmax(axis=2)


def on_modal_residue(xi: np.ndarray, low: int, span: int, moduli: tuple) -> np.ndarray:
    """(span, C, len(moduli)) float32: 1 where reading ``low`` + v of a channel lies on
    that channel's most common residue modulo each step.  Residues are counted from
    each channel's histogram of readings, not reading by reading."""
    channels = xi.shape[1]
    hist = np.bincount((xi + span * np.arange(channels)[None, :]).ravel(),
                       minlength=channels * span).reshape(channels, span)
    return modal_residue(hist, low, moduli)


def modal_residue(hist: np.ndarray, low: int, moduli: tuple) -> np.ndarray:
    """``on_modal_residue`` from each channel's histogram ``hist`` (C, span) of readings
    ``low`` + v."""
    channels, span = hist.shape
    residues = np.mod(np.arange(low, low + span)[:, None], np.array(moduli)[None, :])
    out = np.zeros((span, channels, len(moduli)), np.float32)
    for j, q in enumerate(moduli):
        onehot = (residues[:, j, None] == np.arange(q)[None, :]).astype(np.int64)
        modal = (hist @ onehot).argmax(axis=1)                       # (C,)
        out[:, :, j] = residues[:, j, None] == modal[None, :]
    return out


def pile_ends(hist: np.ndarray) -> np.ndarray | None:
    """(span, C, 2) bool: ``pileup.edge_hits`` by value instead of by sample, from each
    channel's histogram ``hist`` (C, span) of integer readings (the same piles: the most
    common value among each end's outermost ``pileup.TAIL`` of the readings, the
    outermost of equals, and the values within ``pileup.WIDTH`` of it); None when a
    channel spans 1e5 values or more (``pileup`` then finds its piles otherwise).

    All channels at once: the values up to the first whose cumulative count reaches the
    tail's share are the low tail; the high tail is as many distinct values from the top
    (``pileup`` counts them once, from the low end); the first largest count in a tail is
    its pile (empty values never win)."""
    channels, span = hist.shape
    out = np.zeros((span, channels, 2), bool)
    seen = hist > 0
    used = seen.any(axis=1)
    if not used.any():
        return out
    low = np.argmax(seen, axis=1)
    high = span - 1 - np.argmax(seen[:, ::-1], axis=1)
    if (used & (high - low >= 1e5)).any():
        return None
    v = np.arange(span)
    cum = np.cumsum(hist, axis=1)
    reach = np.argmax(cum >= pileup.TAIL * cum[:, -1:], axis=1)       # the low tail's last
    tail = np.cumsum(seen, axis=1)[np.arange(channels), reach]         # its distinct values
    low_pile = np.argmax(np.where(v[None, :] <= reach[:, None], hist, -1), axis=1)
    top = np.cumsum(seen[:, ::-1], axis=1)                # distinct values from the top
    high_pile = span - 1 - np.argmax(np.where(top <= tail[:, None], hist[:, ::-1], -1), axis=1)
    for end, pile in enumerate((low_pile, high_pile)):   # the values within WIDTH of it
        out[:, :, end] = (np.abs(v[:, None] - pile[None, :]) <= pileup.WIDTH) & used[None, :]
    return out


def count(x: np.ndarray, xo: np.ndarray, inorder, cells: tuple, moduli: tuple,
          sums: blocksums.Packer, cut, largest: int) -> None:
    """The parts ``at_mode``, ``residue`` and ``edge`` of integer readings ``x`` (``xo``:
    in block order, as ``inorder`` puts any per-sample array; ``cells``: how many, each
    sample's, and each sample's in block order; ``largest``: the most samples in a block)."""
    labels, cell, cell_in_order = cells
    channels = x.shape[1]
    low = int(x.min()) if x.size else 0
    xi = (x - low).astype(np.int64) if x.size else np.zeros(x.shape, np.int64)
    span = int(xi.max()) + 1 if x.size else 1
    per_cell = cell_counts(xi, cell, labels, span)
    on_mode = xo == (per_cell.argmax(axis=2) + low)[cell_in_order]
    hist = per_cell.sum(axis=0)                 # (C, span), as each channel's bincount
    table = modal_residue(hist, low, moduli).reshape(span * channels, len(moduli))
    at = inorder(xi) * channels + np.arange(channels)[None, :]
    if largest >= 1 << DIGIT:      # too many to pack: each indicator counted apart
        sums.add('at_mode', cut, blocksums.taken(on_mode.astype(np.float32)))
        sums.add('residue', cut, blocksums.taken(np.take(table, at, axis=0)))
        sums.add('edge', cut, blocksums.taken(inorder(pileup.edge_hits(x))))
        return
    ends = pile_ends(hist)          # the pile ends by value, packed with the rest
    code = packed(on_mode, code_table(
        table, None if ends is None else ends.reshape(span * channels, 2)), at)
    if ends is None:
        edge = inorder(pileup.edge_hits(x))
        code += edge[..., 0].astype(np.int64) << (DIGIT * (1 + len(moduli)))
        code += edge[..., 1].astype(np.int64) << (DIGIT * (2 + len(moduli)))
    total = np.zeros((sums.blocks, channels), np.int64)
    if sums.direct:
        cut.add(blocksums.taken(code), total, slice(None))
        digits(total, len(moduli), {k: sums.view(k) for k in ('at_mode', 'residue', 'edge')})
        return
    starts, targets, _ = cut
    if starts.size:
        total[targets] = np.add.reduceat(code, starts, axis=0)
    for name, part in digits(total, len(moduli)).items():
        sums.put(name, part)
