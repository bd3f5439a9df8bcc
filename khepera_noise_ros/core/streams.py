"""Reproducible random draws for a batch of robots.

Every robot-step gets a fixed block of ``CHANNELS`` 16-bit draws, so the
stream a robot sees never depends on the noise settings of that step (a
runtime parameter change does not shift later draws).  Two sources:

* ``BatchStream(seed)`` -- one SFC64 generator for the whole batch; fastest.
* ``RobotStreams(seeds)`` -- a counter-based hash of (robot seed, step,
  channel); a robot's draws do not depend on which batch or worker it is in,
  which is what makes a split evaluation equal an unsplit one.
"""
from __future__ import annotations

from typing import SupportsInt, Union, cast

import numpy as np
import numpy.typing as npt

PERTURB = 0                 # channel of the heading perturbation
SENSOR = slice(1, 9)        # independent noise, one per sensor
GROUP = slice(9, 17)        # dependent noise, one per dependence group (at most 8)
CHANNELS = 20               # 17 used, padded to five 64-bit words
UNIT = 65535.0              # draws are integers 0..UNIT

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)


def _splitmix(z: np.ndarray) -> np.ndarray:
    z = z ^ (z >> np.uint64(30))
    z *= _M1
    z ^= z >> np.uint64(27)
    z *= _M2
    z ^= z >> np.uint64(31)
    return z


class BatchStream:
    """One generator for the batch: draws for step t are the t-th block."""

    def __init__(self, seed: int, robots: int):
        self.robots = robots
        self._bits = np.random.SFC64(int(seed))
        self._next_step = 0

    def draw(self, step: int, channels: int = CHANNELS) -> np.ndarray:
        """(>= channels, robots) uint16 draws for ``step``; steps go in order.

        Drawing only the channels in use (say 8 sensors and 2 groups) saves time;
        the stream stays reproducible because the same settings draw the same amount.
        """
        if step != self._next_step:
            raise ValueError(f'BatchStream draws steps in order: expected {self._next_step}, '
                             f'got {step}')
        self._next_step += 1
        words = -(-min(channels, CHANNELS) // 4)
        raw = self._bits.random_raw(self.robots * words)
        return raw.view(np.uint16).reshape(4 * words, self.robots)


class RobotStreams:
    """One counter-based stream per robot, addressed by (step, channel)."""

    def __init__(self, seeds: npt.ArrayLike) -> None:
        seeds = np.asarray(seeds)
        if seeds.ndim != 1 or seeds.size == 0:
            raise ValueError(f'seeds must be a non-empty 1-D sequence, got shape {seeds.shape}')
        if not np.issubdtype(seeds.dtype, np.integer) or (seeds < 0).any():
            raise ValueError(f'seeds must be non-negative integers, got {seeds[:4]}...')
        self.robots = seeds.size
        self._keys = _splitmix(seeds.astype(np.uint64) * _GOLDEN + _GOLDEN)
        self._channel = np.arange(CHANNELS // 4, dtype=np.uint64)[:, None]

    def draw(self, step: int, channels: int = CHANNELS) -> np.ndarray:
        """(CHANNELS, robots) uint16 draws for ``step``, in any order (all channels, so
        that a robot's draws never depend on the settings)."""
        counter = np.uint64(step) * np.uint64(CHANNELS // 4) + self._channel + np.uint64(1)
        words = _splitmix(self._keys[None, :] + counter * _GOLDEN)
        # each 64-bit word gives four 16-bit draws, for four consecutive channels
        draws: np.ndarray = words.T.copy().view(np.uint16).reshape(self.robots, CHANNELS).T
        return draws


Stream = Union[BatchStream, RobotStreams]


def make_stream(seed: npt.ArrayLike, robots: int) -> Stream:
    """The random stream of a batch of episodes.

    Args:
        seed: an int (one generator for the batch: a BatchStream) or one seed per robot
            (a RobotStreams, what evolution uses).
        robots: B.

    Returns:
        A stream whose ``draw(step, channels)`` gives (channels, B) uint16 draws.

    Raises:
        ValueError: as many seeds as robots are not given.
    """
    if np.ndim(seed) == 0:
        return BatchStream(int(cast(SupportsInt, seed)), robots)
    streams = RobotStreams(seed)
    if streams.robots != robots:
        raise ValueError(f'got {streams.robots} seeds for {robots} robots')
    return streams
