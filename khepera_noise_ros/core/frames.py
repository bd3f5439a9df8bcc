"""The Khepera's light-sensor frames: names and poses in ``base_link``.

``base_link`` is REP 105's body frame: x forward, y left, z up, angles
counter-clockwise positive (REP 103).  Sensor n sits on the rim of the round
body at the bearing ``SENSOR_ANGLES_DEG[n]``, looking outwards along its own
x axis.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

from .khepera import SENSOR_ANGLES_DEG, SENSORS

BASE_FRAME = 'base_link'
BODY_RADIUS_M = 0.0275          # the Khepera is 55 mm across
SENSOR_HEIGHT_M = 0.015         # the sensors sit about half-way up its 30 mm


@dataclass(frozen=True)
class SensorPose:
    """A sensor's frame in ``base_link``: position in metres, yaw in radians (CCW)."""

    frame: str
    x: float
    y: float
    z: float
    yaw: float

    @property
    def quaternion(self) -> tuple[float, float, float, float]:
        """(x, y, z, w) of a rotation by ``yaw`` about z."""
        return 0.0, 0.0, math.sin(self.yaw / 2.0), math.cos(self.yaw / 2.0)


def sensor_frame(sensor: int, prefix: str = '') -> str:
    """The frame id of light sensor ``sensor`` (0..7), e.g. ``light_sensor_3``."""
    if not 0 <= sensor < SENSORS:
        raise ValueError(f'sensor must be 0..{SENSORS - 1}, got {sensor!r}')
    return f'{prefix}light_sensor_{sensor}'


def sensor_poses(prefix: str = '', radius_m: float = BODY_RADIUS_M,
                 height_m: float = SENSOR_HEIGHT_M) -> list[SensorPose]:
    """The eight sensors' poses in ``<prefix>base_link``."""
    poses = []
    for n, deg in enumerate(SENSOR_ANGLES_DEG):
        yaw = math.radians(deg)
        poses.append(SensorPose(sensor_frame(n, prefix), radius_m * math.cos(yaw),
                                radius_m * math.sin(yaw), height_m, yaw))
    return poses
