"""The emulated physical world: robots at fixed positions, a lamp, a room, and the effects.

Pure numpy and in-process (no serial port): the emulator serves it over a
pseudo-terminal, and the diagnosis benchmark and experiment runner may use it
directly.  The light each sensor receives comes from the simulator's geometry
(``core.khepera.World.response``: that is shared physics); everything between
that light and the integer a sensor reports is ``effects.SensorChain``.

Each robot has its own random streams, keyed from ``seed``: one for its
sensors, one for its wheels, each a counter-based hash (splitmix64) of the
robot's key and how often it has been read or turned, so a whole batch draws in
one vectorised pass.  A robot's readings therefore depend only on the seed, its
index and how often it has been read and turned, never on the other robots.
Time is virtual: one ``read`` is one sample period.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtri

from ..core.khepera import DARK, SENSOR_ANGLES_DEG, SENSORS, World
from .effects import DRAWS, EffectsConfig, SensorChain, turn_error

LAMP_OFF_MM = 1e4           # a lamp this far away lights nothing
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_START = np.uint64(0xD1B54A32D192ED03)     # the drift's starting draw: a counter of its own


def _splitmix(z: np.ndarray) -> np.ndarray:
    z = z ^ (z >> np.uint64(30))
    z = z * np.uint64(0xBF58476D1CE4E5B9)
    z = z ^ (z >> np.uint64(27))
    z = z * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


def normals(keys: np.ndarray, counters: np.ndarray, channels: int) -> np.ndarray:
    """(n, channels) standard normal draws, a pure function of each robot's key and
    counter (the inverse normal CDF of 53-bit uniforms, never 0 or 1)."""
    with np.errstate(over='ignore'):
        index = counters.astype(np.uint64)[:, None] * np.uint64(channels) + \
            np.arange(channels, dtype=np.uint64)[None, :]
        bits = _splitmix(keys[:, None] + index * _GOLDEN)
    return ndtri(((bits >> np.uint64(11)).astype(np.float64) + 0.5) * 2.0 ** -53)


@dataclass(frozen=True)
class Condition:
    """A lighting condition: how far the lamp is and how dark the room is.

    ``ambient`` is what a sensor that sees no lamp reads (0 bright .. 525
    dark); ``lamp_distance_mm`` is in the simulator's geometry, where the lamp
    lights nothing beyond ``World.reach_mm``.
    """

    lamp_distance_mm: float = World.lamp_distance_mm
    ambient: float = World.ambient

    def __post_init__(self):
        World(lamp_distance_mm=self.lamp_distance_mm, ambient=self.ambient)   # range checks

    def world(self, geometry: World = World()) -> World:
        return dataclasses.replace(geometry, lamp_distance_mm=self.lamp_distance_mm,
                                   ambient=self.ambient)


# The task's arena, and section 2's four measurements (lamp straight ahead; the labels of
# ``synchrony.PAPER_CORRELATION``), all in the task's light regime: the bright condition
# (1 ft from the bulb) is the task's own lamp, the dark room is the task's room with the
# lamp off, and the 2 ft bulb (lamp 140 mm away in the simulator's geometry) and the lit
# room (ambient 250) give the mid-range readings the side sensors see during the task.
CONDITIONS = {
    'task': Condition(),
    'bulb_1ft': Condition(),
    'bulb_2ft': Condition(lamp_distance_mm=140.0, ambient=World.ambient),
    'room_fluorescent': Condition(lamp_distance_mm=LAMP_OFF_MM, ambient=250.0),
    'room_dark': Condition(lamp_distance_mm=LAMP_OFF_MM, ambient=World.ambient),
}
SECTION2 = ('bulb_1ft', 'bulb_2ft', 'room_fluorescent', 'room_dark')


def condition_named(name) -> Condition:
    if isinstance(name, Condition):
        return name
    if name not in CONDITIONS:
        raise ValueError(f'unknown lighting condition {name!r}; known: {sorted(CONDITIONS)}')
    return CONDITIONS[name]


class EmulatedWorld:
    """``robots`` Kheperas, each in its own copy of the room, under ``config``'s effects."""

    def __init__(self, config: EffectsConfig | None = None, seed: int = 0, robots: int = 1,
                 geometry: World = World(), start_bearing_deg: float | None = None):
        """``start_bearing_deg``: where the experimenter puts the lamp each time a robot is
        placed for an episode (``set_condition``); None leaves the robot as it was."""
        if not isinstance(robots, (int, np.integer)) or robots < 1:
            raise ValueError(f'robots must be an integer >= 1, got {robots!r}')
        if start_bearing_deg is not None and not np.isfinite(start_bearing_deg):
            raise ValueError(f'start_bearing_deg must be finite degrees or None, '
                             f'got {start_bearing_deg!r}')
        self.start_bearing_deg = start_bearing_deg
        self.config = EffectsConfig.real_robot() if config is None else config
        self.geometry = geometry
        self.robots = int(robots)
        sensors, wheels = np.random.SeedSequence(seed).spawn(2)
        self._sensor_key = sensors.generate_state(self.robots, np.uint64)
        self._wheel_key = wheels.generate_state(self.robots, np.uint64)
        self._turns = np.zeros(self.robots, np.uint64)
        start = normals(self._sensor_key ^ _START, np.zeros(self.robots, np.uint64), SENSORS)
        self._chain = SensorChain(self.config, self.robots, start)
        self._bearing = np.zeros(self.robots)
        # each robot's world as an index into the few distinct ones: grouping robots by
        # world is then an array compare, not a dataclass compare per robot
        self._world_list = [geometry]
        self._world_id = np.zeros(self.robots, np.int64)
        self.conditions = [Condition(geometry.lamp_distance_mm, geometry.ambient)] * self.robots
        self.samples = np.zeros(self.robots, np.int64)

    def _rows(self, robot) -> np.ndarray:
        """Robot indices: all for None, one for an int, or those of a sequence."""
        if robot is None:
            return np.arange(self.robots)
        rows = np.atleast_1d(np.asarray(robot))
        if rows.ndim != 1 or not np.issubdtype(rows.dtype, np.integer) \
                or ((rows < 0) | (rows >= self.robots)).any() or np.unique(rows).size < rows.size:
            raise ValueError(f'robot must be an index in [0, {self.robots}) or a sequence of '
                             f'distinct ones, got {robot!r}')
        return rows

    @property
    def bearing_deg(self) -> np.ndarray:
        """Ground truth: lamp bearing in each robot's frame, degrees CCW, in [-180, 180)."""
        return (self._bearing + 180.0) % 360.0 - 180.0

    def set_condition(self, condition: Condition | str, robot=None) -> None:
        """Place the lamp and set the room's light, as the experimenter would."""
        condition = condition_named(condition)
        rows = self._rows(robot)
        for r in rows:
            self.conditions[r] = condition
        world = condition.world(self.geometry)
        if world not in self._world_list:
            self._world_list.append(world)
        self._world_id[rows] = self._world_list.index(world)
        if self.start_bearing_deg is not None:
            self._bearing[rows] = self.start_bearing_deg
        self._chain.placed(rows)

    def set_bearing(self, deg, robot=None) -> None:
        """Put the lamp at ``deg`` in the robot's frame (the experimenter turns the robot)."""
        deg = np.asarray(deg, np.float64)
        if not np.isfinite(deg).all():
            raise ValueError(f'bearing must be finite degrees, got {deg}')
        rows = self._rows(robot)
        self._bearing[rows] = deg
        self._chain.placed(rows)

    def turn(self, deg, robot=None) -> np.ndarray:
        """Turn in place by ``deg`` commanded degrees, positive clockwise (right), which
        moves the lamp counter-clockwise in the robot's frame; returns the actual turn."""
        rows = self._rows(robot)
        deg = np.broadcast_to(np.asarray(deg, np.float64), rows.shape)
        if not np.isfinite(deg).all():
            raise ValueError(f'turn must be finite degrees, got {deg}')
        z = normals(self._wheel_key[rows], self._turns[rows], 1)[:, 0]
        self._turns[rows] += np.uint64(1)
        actual = turn_error(self.config.actuator_turn_error, deg, z)
        self._bearing[rows] += actual
        return actual

    def light(self, rows: np.ndarray) -> np.ndarray:
        """(n, 8) ideal readings: the simulator's light response, no effects."""
        relative = self._bearing[rows, None] - np.asarray(SENSOR_ANGLES_DEG)[None, :]
        out = np.empty((rows.size, SENSORS))
        ids = self._world_id[rows]
        for world_id in np.unique(ids):           # robots under one condition at once
            same = ids == world_id
            out[same] = self._world_list[world_id].response(relative[same])
        return np.clip(out, 0.0, DARK)

    def read(self, robot=None) -> np.ndarray:
        """One sample of the light sensors: (robots, 8) ints; (8,) for an int ``robot``,
        (n, 8) for a sequence of n robots."""
        rows = self._rows(robot)
        z = normals(self._sensor_key[rows], self.samples[rows], DRAWS)
        readings = self._chain.measure(self.light(rows), z, rows)
        self.samples[rows] += 1
        return readings[0] if np.ndim(robot) == 0 and robot is not None else readings


def stationary(world: EmulatedWorld, condition: Condition | str, samples: int,
               bearing_deg: float = 0.0, robot: int = 0) -> np.ndarray:
    """(samples, 8) readings of a robot that stands still: section 2's measurement."""
    world.set_condition(condition, robot)
    world.set_bearing(bearing_deg, robot)
    return np.stack([world.read(robot) for _ in range(samples)])
