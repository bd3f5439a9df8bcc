"""Block sums of the stationary statistics written straight into their packed table.

``gap.statistics`` reduces each block of consecutive samples to sums and packs them
side by side, blocks in stratum order.  For blocks of at most ``SEQUENTIAL`` rows
this module adds each block's rows exactly as ``np.add.reduceat`` does (its first row
plus the sum of the others, added one by one) and writes the sum to the block's row
of the packed table: no per-sample array of products, no reordered copy.  Longer
blocks (numpy adds them pairwise) take the general path, ``Packer(direct=False)``.
"""
from __future__ import annotations

import numpy as np

SEQUENTIAL = 8    # numpy adds the rows after a block's first one by one up to this many


class Segments:
    """Blocks as runs of consecutive positions 0..n-1 (``starts``: each run's first,
    increasing; ``targets``: its block), grouped by size, each with the row its sum
    goes to (``rows``: per block)."""

    def __init__(self, starts: np.ndarray, targets: np.ndarray, n: int, rows: np.ndarray):
        sizes = np.diff(np.r_[starts, n]).astype(np.int64)
        self.largest = int(sizes.max()) if sizes.size else 0
        self.groups = []        # ((m, k) positions: the j-th row of each, output rows)
        for m in np.unique(sizes):
            first = starts[sizes == m]
            self.groups.append((first[None, :] + np.arange(int(m))[:, None],
                                rows[targets[sizes == m]]))

    def add(self, values, out: np.ndarray, cols: slice) -> None:
        """``out[row, cols]`` = the sum of each block's ``values`` (a function of an (m, k)
        array of positions giving (m, k, ...) rows), in their own precision, in
        reduceat's order: the first row plus the others added one by one."""
        for at, rows in self.groups:
            v = values(at)
            total = v[0]
            if len(v) > 1:
                rest = v[1].copy()
                for j in range(2, len(v)):
                    rest += v[j]
                total = total + rest
            out[rows, cols] = total.reshape(rows.size, -1)


def taken(a: np.ndarray):
    """``values`` for ``Packer.add``: the rows of ``a`` at the positions asked (None: all)."""
    return lambda at: a if at is None else np.take(a, at, axis=0)


class Packer:
    """The packed (blocks, D) table of named parts (``shapes``: name -> per-block shape,
    in table order), blocks in ``order``.  With ``rows`` (block -> its row, the inverse
    of ``order``) sums go straight to their rows (``Segments``: *direct*); without, each
    part is summed in block order by ``block_sum`` and the parts are packed and
    reordered at the end (``pack``), the general path.  ``column_major``: the direct
    table stored column by column (Fortran order), for sums over its blocks alone
    (``resample.stratum_sums``: numpy adds each column's blocks in the same order
    either way, ten times faster down a contiguous column)."""

    def __init__(self, shapes: dict, blocks: int, order: np.ndarray,
                 rows: np.ndarray | None = None, column_major: bool = False):
        self.layout, at = {}, 0
        for name, shape in shapes.items():
            size = int(np.prod(shape, dtype=int))
            self.layout[name] = (slice(at, at + size), tuple(shape))
            at += size
        self.blocks, self.order, self.rows = blocks, order, rows
        self.direct = rows is not None
        if not self.direct:
            self.out = None
        elif column_major:      # each column contiguous: sums over blocks run down it
            self.out = np.zeros((at, blocks)).T
        else:
            self.out = np.zeros((blocks, at))
        self.parts: dict = {}

    def cols(self, name: str, index: int | None = None) -> slice:
        """The table's columns of part ``name`` (or of its ``index``-th row)."""
        where, shape = self.layout[name]
        if index is None:
            return where
        width = (where.stop - where.start) // shape[0]
        return slice(where.start + index * width, where.start + (index + 1) * width)

    def add(self, name: str, segments, values, index: int | None = None) -> None:
        """Part ``name`` (its ``index``-th row): block sums of ``values``, a function of
        positions (``taken``; None: all in order); ``segments`` a ``Segments`` when
        direct, else the cut ``block_sum`` takes."""
        if self.direct:
            segments.add(values, self.out, self.cols(name, index))
        else:
            self.parts.setdefault(name, {})[index] = (segments, values)

    def put(self, name: str, per_block: np.ndarray) -> None:
        """Part ``name`` given per block, in block order."""
        if self.direct:
            self.out[self.rows, self.cols(name)] = per_block.reshape(self.blocks, -1)
        else:
            self.parts[name] = per_block

    def put_at(self, name: str, at: np.ndarray, values: np.ndarray) -> None:
        """Part ``name``: ``values`` added to zeros at blocks ``at`` (distinct), else 0."""
        if self.direct:
            if at.size:
                self.out[self.rows[at], self.cols(name)] += values.reshape(at.size, -1)
            return
        part = np.zeros((self.blocks,) + self.layout[name][1])
        if at.size:
            part[at] += values
        self.parts[name] = part

    def view(self, name: str) -> np.ndarray:
        """The table's columns of part ``name`` as (blocks, *shape), rows in table order
        (direct only): written in place."""
        where, shape = self.layout[name]
        out = self.out[:, where].reshape((self.blocks,) + shape)
        if not np.may_share_memory(out, self.out):
            raise ValueError(f'part {name!r} is not a view of the table')
        return out

    def done(self, block_sum, pack) -> tuple[np.ndarray, dict]:
        """(the table, its layout); ``block_sum(cut, values, blocks)`` and ``pack(parts,
        blocks, order)`` finish the general path (parts not given are zeros)."""
        if self.direct:
            return self.out, self.layout
        parts = {}
        for name, (_, shape) in self.layout.items():
            part = self.parts.get(name)
            if part is None:
                part = np.zeros((self.blocks,) + shape)
            elif isinstance(part, dict):
                summed = {i: block_sum(cut, values(None), self.blocks)
                          for i, (cut, values) in part.items()}
                part = summed[None] if None in summed else \
                    np.stack([summed[i] for i in sorted(summed)], axis=1)
            parts[name] = part
        return pack(parts, self.blocks, self.order)
