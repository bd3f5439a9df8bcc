"""``ForeignWorld``: copies of one foreign robot, each at a fixed position before a lamp.

It has the methods the project's serial plumbing drives a world by (``robots``,
``bearing_deg``, ``set_condition``, ``set_bearing``, ``turn``, ``read``), so
``reality.khepera_robot.InProcessRobots`` runs it in this process and
``reality.emulator.Emulator`` serves it on pseudo-terminals.  Each copy has two
counter-based random streams (sensors, wheels) keyed from the robot's ``unit_seed``:
a copy's readings depend only on that seed, its index and its own history.
"""
from __future__ import annotations

import numpy as np

from . import actuator, counter, light
from .sensing import Sensing

SENSOR_DRAWS = 9          # per sample: the lamp's flicker, then 8 cells' shot noise
TURN_DRAWS = 2            # per turn: gain scatter, jitter
_START = 1 << 40          # the sensor counter of the flicker's starting draw
# Lighting conditions by name, in the simulator's units (as the recorder declares them).
CONDITIONS = {'task': (5.0, 500.0), 'bulb_1ft': (14.0, 500.0), 'bulb_2ft': (130.0, 500.0),
              'room_fluorescent': (1e4, 250.0), 'room_dark': (1e4, 500.0)}


class ForeignWorld:
    """``robots`` copies of the robot ``params`` (from ``params.load``)."""

    def __init__(self, params: dict, robots: int = 1, seed: int | None = None,
                 start_bearing_deg: float | None = 0.0):
        """``seed`` replaces the file's ``unit_seed``; ``start_bearing_deg`` is where each
        placement (``set_condition``) puts the lamp, None: where the copy was."""
        if not isinstance(robots, (int, np.integer)) or robots < 1:
            raise ValueError(f'robots must be an integer >= 1, got {robots!r}')
        self.params, self.robots = params, int(robots)
        self.start_bearing_deg = start_bearing_deg
        unit = params['unit_seed'] if seed is None else int(seed)
        self._sensor_key = counter.keys(unit, self.robots, 0)
        self._wheel_key = counter.keys(unit, self.robots, 1)
        self.samples = np.zeros(self.robots, np.int64)
        self.turns = np.zeros(self.robots, np.int64)
        start = counter.normals(self._sensor_key, np.full(self.robots, _START), 1)[:, 0]
        self._sensing = Sensing(params, self.robots, start)
        self._bearing = np.zeros(self.robots)
        self._gears = np.zeros(self.robots)
        self._distance = np.full(self.robots, CONDITIONS['task'][0])
        self._ambient = np.full(self.robots, CONDITIONS['task'][1])

    def _rows(self, robot) -> np.ndarray:
        if robot is None:
            return np.arange(self.robots)
        rows = np.atleast_1d(np.asarray(robot))
        if rows.ndim != 1 or not np.issubdtype(rows.dtype, np.integer) \
                or ((rows < 0) | (rows >= self.robots)).any() or np.unique(rows).size < rows.size:
            raise ValueError(f'robot must be an index in [0, {self.robots}) or distinct ones, '
                             f'got {robot!r}')
        return rows

    @property
    def bearing_deg(self) -> np.ndarray:
        """Ground truth: the lamp's bearing in each copy's frame, degrees CCW, [-180, 180)."""
        return (self._bearing + 180.0) % 360.0 - 180.0

    def set_condition(self, condition, robot=None) -> None:
        """Place the copies under a lighting condition: a name of ``CONDITIONS`` or anything
        with ``lamp_distance_mm`` and ``ambient`` (what a bridge declares)."""
        if isinstance(condition, str):
            if condition not in CONDITIONS:
                raise ValueError(f'unknown lighting condition {condition!r}; known: '
                                 f'{sorted(CONDITIONS)}')
            distance, ambient = CONDITIONS[condition]
        else:
            distance, ambient = float(condition.lamp_distance_mm), float(condition.ambient)
        if not (0.0 <= distance <= 1e4 and 0.0 <= ambient <= light.DARK):
            raise ValueError(f'lamp_distance_mm must be in [0, 10000] and ambient in [0, 525], '
                             f'got {distance!r} and {ambient!r}')
        rows = self._rows(robot)
        self._distance[rows], self._ambient[rows] = distance, ambient
        if self.start_bearing_deg is not None:
            self._bearing[rows] = self.start_bearing_deg
        self._settle(rows)

    def set_bearing(self, deg, robot=None) -> None:
        """Put the lamp at ``deg`` in the copies' frames (the experimenter turns them)."""
        deg = np.asarray(deg, np.float64)
        if not np.isfinite(deg).all():
            raise ValueError(f'bearing must be finite degrees, got {deg}')
        rows = self._rows(robot)
        self._bearing[rows] = deg
        self._settle(rows)

    def turn(self, deg, robot=None) -> np.ndarray:
        """Command a turn in place of ``deg`` degrees, positive clockwise (right), which
        moves the lamp counter-clockwise; returns the turn the wheels made."""
        rows = self._rows(robot)
        deg = np.broadcast_to(np.asarray(deg, np.float64), rows.shape)
        if not np.isfinite(deg).all():
            raise ValueError(f'turn must be finite degrees, got {deg}')
        z = counter.normals(self._wheel_key[rows], self.turns[rows], TURN_DRAWS)
        self.turns[rows] += 1
        made, self._gears[rows] = actuator.execute(self.params['actuator'], deg,
                                                   self._gears[rows], z)
        self._bearing[rows] += made
        return made

    def clean(self, rows: np.ndarray, lamp_gain=1.0) -> np.ndarray:
        """(n, 8) analogue readings of copies ``rows`` now, before dynamics and noise."""
        return light.response(self.params['light'], self._bearing[rows], self._distance[rows],
                              self._ambient[rows], lamp_gain)

    def read(self, robot=None) -> np.ndarray:
        """One sample of the light sensors: (robots, 8) integers; (8,) for an int ``robot``,
        (n, 8) for a sequence of n."""
        rows = self._rows(robot)
        z = counter.normals(self._sensor_key[rows], self.samples[rows], SENSOR_DRAWS)
        self.samples[rows] += 1
        gain = self._sensing.lamp_gain(rows, z[:, 0])
        out = self._sensing.measure(rows, self.clean(rows, gain), z[:, 1:])
        return out[0] if robot is not None and np.ndim(robot) == 0 else out

    def _settle(self, rows: np.ndarray) -> None:
        self._sensing.settle(rows, self.clean(rows, self._sensing.lamp_gain(rows)))
