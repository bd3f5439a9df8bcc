"""The project's block bootstrap: the one block-length rule (Politis and White) and
stratified resampling of per-block sums."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..effects.base import Array

REPLICATES = 200


@dataclass
class Blocks:
    """Per-block sums of one recording, blocks grouped by stratum (kept in stratum order)."""

    kind: str                               # 'stationary' or 'closed_loop'
    channels: tuple[int, ...]
    strata: list[Any]                       # stratum labels
    stratum: np.ndarray                     # (B,) stratum of each block, non-decreasing
    sums: Array                             # (B, D)
    layout: dict[str, tuple[slice, tuple[int, ...]]]
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if np.any(self.stratum[1:] < self.stratum[:-1]):
            order = np.argsort(self.stratum, kind='stable')
            self.stratum, self.sums = self.stratum[order], self.sums[order]
        self.edges = np.searchsorted(self.stratum, np.arange(len(self.strata) + 1))

    def part(self, flat: Array, name: str) -> Array:
        """The ``name`` sums from (..., D) flat sums, reshaped to (..., *shape)."""
        where, shape = self.layout[name]
        out: Array = flat[..., where].reshape(flat.shape[:-1] + shape)
        return out

    def has(self, name: str) -> bool:
        return name in self.layout


def pack(parts: dict[str, Array]) -> tuple[Array, dict[str, tuple[slice, tuple[int, ...]]]]:
    """(B, D) doubles of the named (B, ...) parts side by side, and where each lies."""
    layout, at = {}, 0
    for name, value in parts.items():
        size = math.prod(value.shape[1:])
        layout[name] = (slice(at, at + size), tuple(value.shape[1:]))
        at += size
    out = np.concatenate([v.reshape(len(v), -1) for v in parts.values()], axis=1,
                         dtype=np.float64)
    return out, layout


def weights(blocks: Blocks, replicates: int, rng: np.random.Generator) -> Array:
    """(1 + R, B) block weights: the full data, then stratified bootstrap draws."""
    w = np.zeros((1 + replicates, blocks.stratum.size))
    w[0] = 1.0
    for lo, hi in zip(blocks.edges[:-1], blocks.edges[1:]):
        if replicates and hi > lo:
            picks = rng.integers(lo, hi, size=(replicates, hi - lo)) - lo
            picks += np.arange(replicates)[:, None] * (hi - lo)     # counted per replicate
            w[1:, lo:hi] = np.bincount(picks.ravel(), minlength=picks.size).reshape(picks.shape)
    return w


def resampled(blocks: Blocks, replicates: int, seed: int, w: Array | None = None) -> Array:
    """(1 + R, S, D) each stratum's sums for the full data and ``replicates`` resamples
    (``w``: the ``weights`` of ``seed``, when known)."""
    out = np.zeros((1 + replicates, len(blocks.strata), blocks.sums.shape[1]))
    lo, hi = blocks.edges[:-1], blocks.edges[1:]
    used = np.flatnonzero(hi > lo)
    if used.size == len(blocks.sums):           # a block per stratum: its sums
        out[0, used] = blocks.sums
    else:                                       # ``np.add.reduceat``'s sums, row by row
        for s in used:
            out[0, s] = blocks.sums[lo[s]] + _pairwise(blocks.sums[lo[s] + 1:hi[s]])
    if replicates:
        w = weights(blocks, replicates, np.random.default_rng(seed)) if w is None else w
        for s in used:
            out[1:, s] = w[1:, lo[s]:hi[s]] @ blocks.sums[lo[s]:hi[s]]
    return out


def _pairwise(rows: Array) -> Array:
    """numpy's pairwise sum of ``rows`` (eight running sums to 128 rows, halves beyond):
    the same numbers without its walk down each column of a wide table."""
    n = len(rows)
    if n > 128:
        half = n // 2 - n // 2 % 8
        return _pairwise(rows[:half]) + _pairwise(rows[half:])
    m = n - n % 8
    r = rows[:m].reshape(m // 8, 8, -1).sum(axis=0) if m else np.full((8, rows.shape[1]), -0.0)
    out: Array = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7])) if m else r[0]
    for row in rows[m:]:
        out += row
    return out


def block_length(x: Array, segments: list[slice], minimum: int = 1,
                 maximum: int | None = None) -> int:
    """Block length for centred series ``x`` (N, C) made of ``segments``; at least
    ``minimum``, at most ``maximum`` (default: a third of the shortest segment)."""
    n = min(s.stop - s.start for s in segments)
    top = max(minimum, n // 3 if maximum is None else maximum)
    if n < 6:
        return int(max(1, minimum))
    acov = autocovariance(x, segments, max_lag=n // 2)
    lengths = [politis_white(acov[:, c], n) for c in range(x.shape[1]) if acov[0, c] > 0]
    return int(min(max(max(lengths, default=1), minimum), top))


def autocovariance(x: Array, segments: list[slice], max_lag: int) -> Array:
    """(max_lag + 1, C) autocovariance of centred x pooled over segments (each segment's
    lagged products from its zero-padded power spectrum: no product wraps around)."""
    out = np.zeros((max_lag + 1, x.shape[1]))
    total = sum(s.stop - s.start for s in segments)
    for s in segments:
        seg = np.asarray(x[s], np.float64)
        lags = min(max_lag, len(seg) - 1) + 1
        if lags < 1:
            continue
        size = 1 << int(2 * len(seg) - 1).bit_length()
        f = np.fft.rfft(seg, size, axis=0)
        out[:lags] += np.fft.irfft(f.real ** 2 + f.imag ** 2, size, axis=0)[:lags]
    out /= total
    return out


def politis_white(acov: Array, n: int) -> float:
    """Optimal circular-block length of one series from its autocovariance."""
    rho = acov[1:] / acov[0]
    k_n = max(5, int(math.sqrt(math.log10(n))))
    small = np.abs(rho) < 2 * math.sqrt(math.log10(n) / n)
    m = next((m for m in range(len(rho) - k_n + 1) if small[m:m + k_n].all()), len(rho) // 2)
    big_m = min(2 * max(m, 1), len(rho))
    lags = np.arange(1, big_m + 1)
    t = lags / big_m
    flat_top = np.where(t <= 0.5, 1.0, 2 * (1 - t))
    g = acov[0] + 2 * (flat_top * acov[lags]).sum()
    big_g = 2 * (flat_top * lags * acov[lags]).sum()
    if g <= 0 or big_g == 0:
        return 1.0
    return float(max(1.0, round((2 * big_g ** 2 / (4 / 3 * g ** 2)) ** (1 / 3) * n ** (1 / 3))))
