"""The Khepera at a fixed position: sensor geometry, light response, turning.

Bearings are the lamp's direction in the robot frame, counter-clockwise
positive (REP 103), 0 = lamp straight ahead.  The simulated world keeps them
on a grid of tenths of a degree, so the light response is an exact table
lookup rather than a cosine per sensor per step.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import numpy.typing as npt

SENSORS = 8
FRONT = 6                    # s0..s5 face forward; the task uses only these
DARK = 525.0                 # darkest possible reading (and the clip limit)
# Sensor axes in degrees, Khepera numbering: s0 left ... s5 right, s6/s7 at the back.
SENSOR_ANGLES_DEG = (90.0, 45.0, 10.0, -10.0, -45.0, -90.0, -170.0, 170.0)
TENTHS = 3600                # bearing grid: tenths of a degree in a full turn


@dataclass(frozen=True)
class World:
    """Lamp geometry and light response (after Michel's Khepera Simulator 2.0).

    A sensor reads ``ambient`` in the dark; a lamp within ``half_angle_deg`` of
    its axis lowers that by ``cos(1.5 * angle) * (reach - dist) / reach * gain``,
    floored at ``floor``.  ``deg_per_power`` is the rotation of one step at
    power 1 (power 9 turns 9 times as far).
    """

    lamp_distance_mm: float = 5.0
    ambient: float = 500.0
    gain: float = 500.0
    reach_mm: float = 250.0
    half_angle_deg: float = 60.0
    floor: float = 50.0
    deg_per_power: float = 3.0

    def __post_init__(self) -> None:
        _check_range('lamp_distance_mm', self.lamp_distance_mm, 0.0, 1e4)
        _check_range('ambient', self.ambient, 0.0, DARK)
        _check_range('floor', self.floor, 0.0, DARK)
        _check_range('gain', self.gain, 0.0, DARK)
        _check_range('reach_mm', self.reach_mm, 1e-6, 1e4)
        _check_range('half_angle_deg', self.half_angle_deg, 0.0, 180.0)
        _check_range('deg_per_power', self.deg_per_power, 0.1, 40.0)
        if abs(self.deg_per_power * 10 - round(self.deg_per_power * 10)) > 1e-9:
            raise ValueError(f'deg_per_power must be a multiple of 0.1 deg, got '
                             f'{self.deg_per_power}')

    def response(self, relative_deg: np.ndarray) -> np.ndarray:
        """Noise-free reading of a sensor whose axis is ``relative_deg`` away from the lamp.

        Args:
            relative_deg: angles between sensor axes and the lamp, degrees, any shape.

        Returns:
            Readings of the same shape, ``floor`` .. ``ambient`` (0 bright, 525 dark).
        """
        a = np.radians(np.abs((np.asarray(relative_deg) + 180.0) % 360.0 - 180.0))
        near = max(self.reach_mm - self.lamp_distance_mm, 0.0) / self.reach_mm
        drop = np.where(a < np.radians(self.half_angle_deg), np.cos(1.5 * a) * near * self.gain, 0)
        return np.maximum(self.ambient - drop, self.floor)

    def light_table(self, rounded: bool = True) -> np.ndarray:
        """Every sensor's integer reading at every bearing of the grid (``rounded=False``:
        the light level itself, for noise added before rounding).

        Returns:
            (SENSORS, TENTHS) float32, column ``to_tenths(bearing)``.
        """
        bearing = np.arange(TENTHS) / 10.0
        rel = bearing[None, :] - np.asarray(SENSOR_ANGLES_DEG)[:, None]
        level = self.response(rel)
        return (np.rint(level) if rounded else level).astype(np.float32)

    @property
    def tenths_per_power(self) -> int:
        """Grid steps (tenths of a degree) that one unit of power turns."""
        return int(round(self.deg_per_power * 10))


WORLD_KEYS = tuple(f.name for f in fields(World))     # the world's parameters, by name


def _check_range(name: str, value: float, low: float, high: float) -> None:
    if not np.isfinite(value) or not low <= value <= high:
        raise ValueError(f'{name} must be a finite number in [{low}, {high}], got {value!r}')


def to_tenths(bearing_deg: npt.ArrayLike) -> np.ndarray:
    """Bearings to grid indices.

    Args:
        bearing_deg: bearings in degrees, any shape and range.

    Returns:
        int32 indices 0 .. TENTHS - 1 of the nearest tenth of a degree.
    """
    return (np.rint(np.asarray(bearing_deg, dtype=np.float64) * 10).astype(np.int64)
            % TENTHS).astype(np.int32)


def to_degrees(tenths: np.ndarray) -> np.ndarray:
    """Grid indices to bearings.

    Args:
        tenths: grid indices, wrapped or not.

    Returns:
        Bearings in degrees in [-180, 180).
    """
    return ((np.asarray(tenths) + TENTHS // 2) % TENTHS - TENTHS // 2) / 10.0


def turn(tenths: np.ndarray, direction: np.ndarray, power: np.ndarray,
         world: World) -> np.ndarray:
    """New lamp bearing after a turn: right (+1) moves the lamp to the left (+).

    The grid index is left unwrapped (``% TENTHS`` or ``to_degrees`` wrap it), so
    that callers wrap once per step rather than once per turn.

    Args:
        tenths: (B,) the lamp's bearings as grid indices.
        direction: (B,) -1 left or +1 right (clockwise), the paper's first output.
        power: (B,) 0..9, the paper's second output.
        world: gives the rotation of one unit of power.

    Returns:
        (B,) new grid indices, unwrapped.
    """
    step: np.ndarray = direction * power
    step *= world.tenths_per_power
    step += tenths
    return step
