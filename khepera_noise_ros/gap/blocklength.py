"""The one block-length rule of the project's block bootstraps.

Politis and White (2004), with the correction of Patton, Politis and White
(2009), for the circular (moving) block bootstrap: per series, the flat-top
lag window's estimates of the spectrum at zero (g) and of its derivative (G)
give b = (2 G^2 / (4/3 g^2))^(1/3) n^(1/3).  Several series (sensors) take the
longest any of them needs: white noise gets short blocks, slow drift long ones.
Stretches (episodes, runs) are separate: autocovariances are pooled within
them, never across.  ``synchrony`` and ``gap.statistics`` both use it; each
clamps the result to what its blocks must hold.
"""
from __future__ import annotations

import math

import numpy as np


def block_length(x: np.ndarray, segments: list[slice], minimum: int = 1,
                 maximum: int | None = None) -> int:
    """Block length for centred series ``x`` (N, C) made of the ``segments``; at least
    ``minimum``, at most ``maximum`` (default: a third of the shortest segment)."""
    n = min(s.stop - s.start for s in segments)
    top = max(minimum, n // 3 if maximum is None else maximum)
    if n < 6:
        return int(max(1, minimum))
    acov = autocovariance(x, segments, max_lag=n // 2)          # (lags + 1, C)
    lengths = [politis_white(acov[:, c], n) for c in range(x.shape[1]) if acov[0, c] > 0]
    return int(min(max(max(lengths, default=1), minimum), top))


def autocovariance(x: np.ndarray, segments: list[slice], max_lag: int) -> np.ndarray:
    """(max_lag + 1, C) autocovariance of centred x, pooled over segments.  Each segment's
    lagged products are summed through its power spectrum (zero-padded, so no product
    wraps around): the same sums as lag by lag to rounding, in one transform."""
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
    return out / total


def politis_white(acov: np.ndarray, n: int) -> float:
    """Optimal circular-block length of one series from its autocovariance."""
    rho = acov[1:] / acov[0]
    k_n = max(5, int(math.sqrt(math.log10(n))))
    bound = 2 * math.sqrt(math.log10(n) / n)
    small = np.abs(rho) < bound
    m = next((m for m in range(len(rho) - k_n + 1) if small[m:m + k_n].all()), len(rho) // 2)
    big_m = min(2 * max(m, 1), len(rho))
    lags = np.arange(1, big_m + 1)
    t = lags / big_m
    flat_top = np.where(t <= 0.5, 1.0, 2 * (1 - t))
    g = acov[0] + 2 * (flat_top * acov[lags]).sum()
    big_g = 2 * (flat_top * lags * acov[lags]).sum()
    if g <= 0 or big_g == 0:
        return 1.0
    return max(1.0, round((2 * big_g ** 2 / (4 / 3 * g ** 2)) ** (1 / 3) * n ** (1 / 3)))
