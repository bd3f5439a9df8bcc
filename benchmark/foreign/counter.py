"""Counter-based random numbers (Widynski's "squares" generator) for the foreign robots.

A draw is a pure function of a robot's key and a counter, so what a robot draws does not
depend on which other robots share its batch, nor on whether it is served in this
process or on a pseudo-terminal.
"""
from __future__ import annotations

import numpy as np

_HALF = np.uint64(32)


def keys(seed: int, robots: int, stream: int) -> np.ndarray:
    """(robots,) odd uint64 keys of one stream (sensors 0, wheels 1) of a robot's copies."""
    words = np.random.SeedSequence([int(seed), int(stream)]).generate_state(robots, np.uint64)
    return words | np.uint64(1)


def _swap(x: np.ndarray) -> np.ndarray:
    return (x >> _HALF) | (x << _HALF)


def uniforms(key: np.ndarray, counter: np.ndarray, channels: int) -> np.ndarray:
    """(n, channels) uniforms in (0, 1): draw ``counter * channels + c`` of each key."""
    ctr = counter.astype(np.uint64)[:, None] * np.uint64(channels) \
        + np.arange(channels, dtype=np.uint64)[None, :]
    k = key.astype(np.uint64)[:, None]
    y = ctr * k
    z = y + k
    x = _swap(y * y + y)
    x = _swap(x * x + z)
    x = _swap(x * x + y)
    bits = (x * x + z) >> _HALF
    return (bits.astype(np.float64) + 0.5) * 2.0 ** -32


def normals(key: np.ndarray, counter: np.ndarray, channels: int) -> np.ndarray:
    """(n, channels) standard normals by Box and Muller from ``2 * channels`` uniforms."""
    u = uniforms(key, counter, 2 * channels)
    radius = np.sqrt(-2.0 * np.log(u[:, :channels]))
    return radius * np.cos(2.0 * np.pi * u[:, channels:])
