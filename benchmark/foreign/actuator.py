"""A foreign robot's wheels: how far it really turns for a commanded turn.

Unlike the simulator's exact 3 degrees per unit of power, the executed turn has a
dead-band (static friction eats small commands), gear backlash (a reversal first takes up
the slack), a gain that differs left and right and grows non-linearly with the command,
and scatter.  The task's heading knocks are commanded through the same wheels.
"""
from __future__ import annotations

import numpy as np

REFERENCE_DEG = 10.0      # the command at which the non-linear gain equals ``gain``


def mean_turn(actuator: dict, commanded_deg, reversing=False) -> np.ndarray:
    """The executed turn without scatter, degrees (positive clockwise, as commanded)."""
    c = np.asarray(commanded_deg, np.float64)
    size = np.abs(c) - np.where(reversing, actuator['backlash_deg'], 0.0)
    size = np.maximum(size - actuator['dead_band_deg'], 0.0)
    side = actuator['gain'] * (1.0 + np.sign(c) * actuator['asymmetry'])
    return np.sign(c) * side * REFERENCE_DEG * (size / REFERENCE_DEG) ** actuator['exponent']


def execute(actuator: dict, commanded_deg: np.ndarray, last_sign: np.ndarray,
            z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Executed turns of n robots and the direction their gears are now loaded in.

    Args:
        commanded_deg: (n,) commanded turns, positive clockwise (right).
        last_sign: (n,) the direction of each robot's last turn, 0 before any.
        z: (n, 2) standard normals: the gain's scatter and an additive jitter.
    """
    sign = np.sign(commanded_deg)
    reversing = (last_sign != 0) & (sign != last_sign)
    mean = mean_turn(actuator, commanded_deg, reversing)
    size = np.abs(mean) * np.exp(actuator['scatter'] * z[:, 0])
    size = np.maximum(size + actuator['jitter_deg'] * z[:, 1] * (size > 0), 0.0)
    return sign * size, np.where(sign != 0, sign, last_sign)
