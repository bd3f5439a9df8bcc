"""Per-block counts and products of the stationary block sums (``gap.statistics``): the
upper-triangle products of residuals, each channel's modal reading and modal residues,
and the 0/1 indicators of a sample counted together, packed as digits of one integer."""
from __future__ import annotations

import numpy as np


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


def counted(block: tuple, nb: int, on_mode: np.ndarray, table: np.ndarray, at: np.ndarray,
            edge: np.ndarray) -> dict:
    """Per block and channel, how many samples are at the cell's mode, on each modal
    residue and at each pile end: the nine 0/1 indicators of a sample packed as digits of
    ``DIGIT`` bits in one integer and summed at once (exact while every block has fewer
    than 2 ** ``DIGIT`` samples, the same counts as summing each indicator)."""
    q = table.shape[1]
    shifts = DIGIT * np.arange(2 + q + 1, dtype=np.int64)
    residue = (table.astype(np.int64) << shifts[1:1 + q]).sum(axis=1)
    code = on_mode.astype(np.int64) + np.take(residue, at)
    code += edge[..., 0].astype(np.int64) << shifts[1 + q]
    code += edge[..., 1].astype(np.int64) << shifts[2 + q]
    starts, targets, dense = block
    counts = np.zeros((nb, code.shape[1]), np.int64)
    if starts.size:
        counts[targets] = np.add.reduceat(code, starts, axis=0)
    digits = ((counts[..., None] >> shifts) & ((1 << DIGIT) - 1)).astype(np.float64)
    return {'at_mode': digits[..., 0], 'residue': digits[..., 1:1 + q],
            'edge': digits[..., 1 + q:]}


def cell_modes(xi: np.ndarray, cell: np.ndarray, cells: int, span: int) -> np.ndarray:
    """(cells, C) the most common reading of each channel in each cell (``xi``: integer
    readings less their least, all below ``span``)."""
    channels = xi.shape[1]
    code = ((cell[:, None] * channels + np.arange(channels)[None, :]) * span + xi).ravel()
    counts = np.bincount(code, minlength=cells * channels * span)
    return counts.reshape(cells, channels, span).argmax(axis=2)


def on_modal_residue(xi: np.ndarray, low: int, span: int, moduli: tuple) -> np.ndarray:
    """(span, C, len(moduli)) float32: 1 where reading ``low`` + v of a channel lies on
    that channel's most common residue modulo each step.  Residues are counted from
    each channel's histogram of readings, not reading by reading."""
    channels = xi.shape[1]
    hist = np.bincount((xi + span * np.arange(channels)[None, :]).ravel(),
                       minlength=channels * span).reshape(channels, span)
    residues = np.mod(np.arange(low, low + span)[:, None], np.array(moduli)[None, :])
    out = np.zeros((span, channels, len(moduli)), np.float32)
    for j, q in enumerate(moduli):
        onehot = (residues[:, j, None] == np.arange(q)[None, :]).astype(np.int64)
        modal = (hist @ onehot).argmax(axis=1)                       # (C,)
        out[:, :, j] = residues[:, j, None] == modal[None, :]
    return out
