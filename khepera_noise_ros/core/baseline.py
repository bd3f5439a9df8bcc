"""A hand-written controller that turns toward the brighter side.

It is the yardstick for the task: what a person would write in five minutes.
The paper's evolved controller scored 0.818 on its Figure 8 test.
"""
from __future__ import annotations

import numpy as np

from .network import LEFT, RIGHT


def turn_toward_light(readings: np.ndarray, gain: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Turn toward the brighter (lower-reading) side, harder the larger the imbalance.

    Args:
        readings: (B, SENSORS) readings.
        gain: power per unit of imbalance between the left and right front readings.

    Returns:
        (direction, power), int32 arrays of shape (B,).
    """
    left = readings[:, 0:3].mean(axis=1)
    right = readings[:, 3:6].mean(axis=1)
    direction = np.where(left < right, LEFT, RIGHT).astype(np.int32)
    power = np.clip(np.rint(np.abs(left - right) * gain), 1, 9).astype(np.int32)
    return direction, power
