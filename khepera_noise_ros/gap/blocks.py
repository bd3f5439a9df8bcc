"""The data types of the gap statistics: a statistic's ``Key``, a set of bootstrapped
``Stats``, and a recording's per-block sufficient sums (``Blocks``)."""
from __future__ import annotations

import functools
import warnings
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

FACTORS = ('balance', 'intensity', 'turning')
MODULI = (2, 3, 4, 5, 8, 10)     # quantisation steps tested by the granularity families


class Key(NamedTuple):
    family: str
    sensors: tuple
    condition: str | None
    part: str | None


@dataclass
class Stats:
    """Values of many statistics: ``values`` is (R, K), row 0 the full-data estimate."""

    keys: list[Key]
    values: np.ndarray

    @property
    def estimate(self) -> np.ndarray:
        return self.values[0]

    @functools.cached_property
    def variance(self) -> np.ndarray:
        """Bootstrap variance of each statistic (0 when there are no replicates)."""
        if self.values.shape[0] < 3:
            return np.zeros(len(self.keys))
        with warnings.catch_warnings():
            warnings.simplefilter('ignore', RuntimeWarning)     # all-NaN columns give NaN
            return np.nanvar(self.values[1:], axis=0, ddof=1)

    def index(self) -> dict[Key, int]:
        return {k: i for i, k in enumerate(self.keys)}

    def __add__(self, other: 'Stats') -> 'Stats':
        rows = min(self.values.shape[0], other.values.shape[0])
        return Stats(self.keys + other.keys,
                     np.concatenate([self.values[:rows], other.values[:rows]], axis=1))


@dataclass
class Blocks:
    """Per-block sufficient sums of one recording, and how blocks group into strata."""

    kind: str                             # 'stationary' or 'closed_loop'
    channels: tuple                       # channel numbers of the columns
    strata: list                          # stratum labels
    stratum: np.ndarray                   # (B,) stratum index of each block
    sums: np.ndarray                      # (B, D) flattened sums
    layout: dict                          # name -> (slice, shape) into D
    extra: dict = field(default_factory=dict)   # facts the statistics need

    def __post_init__(self):
        if np.any(self.stratum[1:] < self.stratum[:-1]):     # each stratum's blocks together
            order = np.argsort(self.stratum, kind='stable')
            self.stratum, self.sums = self.stratum[order], self.sums[order]
        self.edges = np.searchsorted(self.stratum, np.arange(len(self.strata) + 1))

    def part(self, flat: np.ndarray, name: str) -> np.ndarray:
        """The ``name`` sums from (..., D) flat sums, reshaped to (..., *shape)."""
        where, shape = self.layout[name]
        return flat[..., where].reshape(flat.shape[:-1] + shape)


def pack(parts: dict[str, np.ndarray], blocks: int,
         order: np.ndarray | None = None) -> tuple[np.ndarray, dict]:
    """(blocks, D) doubles of the named parts side by side, and where each lies; with
    ``order``, the rows taken in that order (one gather of whole rows: five times faster
    than a strided one per part)."""
    layout, at = {}, 0
    for name, value in parts.items():
        shape = value.shape[1:]
        size = int(np.prod(shape, dtype=int))
        layout[name] = (slice(at, at + size), shape)
        at += size
    out = np.empty((blocks, at))
    for name, value in parts.items():
        flat = value.reshape(blocks, layout[name][0].stop - layout[name][0].start)
        out[:, layout[name][0]] = flat
    return (out if order is None else out[order]), layout
