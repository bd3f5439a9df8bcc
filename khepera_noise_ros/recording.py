"""Recordings in the public format (DESIGN.md): CSV plus YAML manifest, and rosbag2 (MCAP).

The in-memory form is ``Recording``: one row per sample.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

FORMAT = 'khepera-noise-recording/1'
COLUMNS = ('episode', 'step', 'heading_deg', 'condition') + tuple(f's{i}' for i in range(8)) \
    + ('direction', 'power')


@dataclass
class Recording:
    """Samples of C light channels (8 for a Khepera); NaN where a value is not known."""

    episode: np.ndarray        # (N,) int
    step: np.ndarray           # (N,) int
    heading_deg: np.ndarray    # (N,) float, NaN where unknown (closed loop on hardware)
    condition: np.ndarray      # (N,) str, keys of manifest['conditions']
    readings: np.ndarray       # (N, C) float, 0 brightest .. 525 darkest on a Khepera
    direction: np.ndarray      # (N,) float, -1 left / +1 right, NaN in stationary data
    power: np.ndarray          # (N,) float, 0..9, NaN in stationary data
    manifest: dict = field(default_factory=dict)
