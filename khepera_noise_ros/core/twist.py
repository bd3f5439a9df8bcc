"""Turn commands in REP 103 terms: a yaw rate (rad/s, counter-clockwise positive) to
and from the Khepera's direction (-1 left, +1 right) and power 0..9.

A step at power p turns ``p * deg_per_power`` degrees; at ``rate_hz`` steps a
second that is a yaw rate of ``p * deg_per_power * rate_hz`` degrees a second.
A left turn (direction -1) is counter-clockwise, so positive in REP 103.
"""
from __future__ import annotations

import math
from typing import NamedTuple

MAX_POWER = 9


class Turn(NamedTuple):
    direction: int          # -1 left (CCW), +1 right (CW)
    power: int              # 0..9
    clipped: bool           # the rate asked for was beyond power 9


def rad_per_power(deg_per_power: float, rate_hz: float) -> float:
    """The yaw rate of one unit of power, rad/s."""
    return math.radians(deg_per_power) * rate_hz


def yaw_rate(direction: int, power: int, deg_per_power: float, rate_hz: float) -> float:
    """The yaw rate (rad/s, CCW positive) of a turn command."""
    if direction not in (-1, 1) or not 0 <= power <= MAX_POWER:
        raise ValueError(f'direction must be -1 or +1 and power 0..{MAX_POWER}, '
                         f'got {direction!r} and {power!r}')
    return -direction * power * rad_per_power(deg_per_power, rate_hz)


def turn_for(rate_rad_s: float, deg_per_power: float, rate_hz: float) -> Turn:
    """The turn command nearest a yaw rate (rad/s, CCW positive), power clipped to 9.

    Raises ValueError for a rate that is not a finite number."""
    if not isinstance(rate_rad_s, (int, float)) or not math.isfinite(rate_rad_s):
        raise ValueError(f'angular.z must be a finite yaw rate in rad/s, got {rate_rad_s!r}')
    power = round(abs(rate_rad_s) / rad_per_power(deg_per_power, rate_hz))
    direction = -1 if rate_rad_s > 0 else 1
    return Turn(direction, min(power, MAX_POWER), power > MAX_POWER)
