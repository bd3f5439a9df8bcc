"""A foreign robot's light response: lobes over the lamp's bearing, and a saturating cell.

Each sensor has its own axis, a lobe whose half-width differs on its two sides and whose
shape runs from peaked to flat-topped, a leak (some lamp light from any direction), and
a sensitivity.  The lamp's light falls with the square of the distance (never to zero,
unlike the simulator's linear reach); the room adds light of its own.  A photocell turns
the total light into a reading that saturates towards its floor (a Hill curve), rather
than the simulator's linear drop clipped at a floor.
"""
from __future__ import annotations

import numpy as np

DARK = 525.0              # the task's darkest reading (0 bright .. 525 dark)
_LN2 = np.log(2.0)


def lobe(light: dict, bearing_deg: np.ndarray) -> np.ndarray:
    """(n, 8) fraction of the lamp's light each sensor takes in at lamp bearing (n,)."""
    delta = (np.asarray(bearing_deg, np.float64)[:, None] - light['axis_deg'][None, :]
             + 180.0) % 360.0 - 180.0            # > 0: the lamp is counter-clockwise
    width = np.where(delta > 0, light['width_ccw_deg'], light['width_cw_deg'])
    core = np.exp(-_LN2 * (np.abs(delta) / width) ** light['shape'])
    return light['leak'] + (1.0 - light['leak']) * core


def lamp_light(light: dict, distance_mm: np.ndarray) -> np.ndarray:
    """(n,) the lamp's light at the robot: inverse square beyond a near-field distance."""
    near = light['lamp_near_mm']
    return light['lamp_power'] * (near / (np.asarray(distance_mm, np.float64) + near)) ** 2


def room_light(light: dict, ambient: np.ndarray) -> np.ndarray:
    """(n,) the room's light: ``ambient`` is what the simulator's sensors read with the lamp
    off (525 black .. 0 bright), so the room gives light in proportion to 525 - ambient."""
    return light['room_flux'] * (DARK - np.asarray(ambient, np.float64)) / DARK


def reading(light: dict, flux: np.ndarray) -> np.ndarray:
    """(n, 8) analogue readings of the cells for total light ``flux`` (n, 8)."""
    x = np.maximum(flux * light['sensitivity'], 0.0) ** light['hill']
    return light['floor'] + (light['dark'] - light['floor']) / (1.0 + x)


def response(light: dict, bearing_deg, distance_mm, ambient, lamp_gain=1.0) -> np.ndarray:
    """(n, 8) noise-free readings at lamp bearings (n,) under a lighting condition; the
    lamp's own light is scaled by ``lamp_gain`` (its flicker)."""
    bearing = np.atleast_1d(np.asarray(bearing_deg, np.float64))
    n = bearing.size
    lamp = np.broadcast_to(lamp_light(light, distance_mm) * lamp_gain, (n,))
    room = np.broadcast_to(room_light(light, ambient), (n,))
    return reading(light, lamp[:, None] * lobe(light, bearing) + room[:, None])
