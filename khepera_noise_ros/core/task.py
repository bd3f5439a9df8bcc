"""The light-centring episode of section 4.2, vectorised over a batch of robots.

A robot at a fixed position turns to face a lamp.  Every ``perturb_every``
steps (step 0 included) its heading is knocked by a uniform random angle.  At
each step it reads its sensors, the controller answers with a turn, and the
step scores balance x intensity x turning on the front six readings.  The
episode's fitness is the mean over its steps.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Literal, overload

import numpy as np
import numpy.typing as npt

from . import streams
from .khepera import DARK, TENTHS, World, to_degrees, to_tenths, turn
from .noise import NoiseModel, realrand

# A step moves a bearing by at most 9 x 40 deg of turn plus a 180 deg knock, so wrapping
# every few steps keeps the grid index a few turns from the table.
WRAP_EVERY = 8
# (B, SENSORS) readings -> (direction (B,), power (B,))
Policy = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class Task:
    """The episode's settings; a bad value is a ValueError naming it.

    Args:
        steps: control steps per episode, >= 1.
        perturb_every: steps between heading knocks (step 0 included), >= 1.
        perturbation_deg: a knock is uniform in +-perturbation_deg, in [0, 180].
    """

    steps: int = 60
    perturb_every: int = 5
    perturbation_deg: float = 25.0

    def __post_init__(self) -> None:
        for name, low in (('steps', 1), ('perturb_every', 1)):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or value < low:
                raise ValueError(f'{name} must be an integer >= {low}, got {value!r}')
        if not np.isfinite(self.perturbation_deg) or not 0 <= self.perturbation_deg <= 180:
            raise ValueError(f'perturbation_deg must be in [0, 180], got '
                             f'{self.perturbation_deg!r}')


def knock_tenths(perturb_draws: np.ndarray, task: Task) -> np.ndarray:
    """The heading knocks of one step.

    Args:
        perturb_draws: (B,) uint16 draws of the PERTURB stream channel.
        task: gives the knock's range.

    Returns:
        (B,) int32 knocks in tenths of a degree, within +-1800 (not wrapped).
    """
    knock = (2 * realrand(perturb_draws) - 1) * task.perturbation_deg
    return np.rint(knock.astype(np.float64) * 10).astype(np.int32)


def knock_deg(perturb_draws: np.ndarray, task: Task) -> np.ndarray:
    """``knock_tenths`` in degrees on the 0.1 deg grid, in [-180, 180); the hardware
    bridge uses it so that simulator and robot get the same knocks."""
    return to_degrees(knock_tenths(perturb_draws, task))


def fitness_factors(readings: np.ndarray, power: npt.ArrayLike
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The paper's three factors of a step's fitness.

    Args:
        readings: (B, >=6) float32 readings (any leading axes, such as steps, may precede B).
        power: (B,) commanded power.

    Returns:
        (balance, intensity, turning), each of power's shape, float32.
    """
    # in place where possible: the same operations in the same order, fewer temporaries
    left = readings[..., 0] + readings[..., 1]
    left += readings[..., 2]
    left *= np.float32(1 / 3)
    right = readings[..., 3] + readings[..., 4]
    right += readings[..., 5]
    right *= np.float32(1 / 3)
    balance = np.subtract(left, right, out=left)
    np.abs(balance, out=balance)
    balance *= np.float32(1 / DARK)
    np.subtract(1.0, balance, out=balance)
    intensity = readings[..., 2] + readings[..., 3]
    intensity *= np.float32(0.5 / DARK)
    np.subtract(1.0, intensity, out=intensity)
    turning = (np.asarray(power) != 0).astype(np.float32)
    return balance, intensity, turning


def step_fitness(readings: np.ndarray, power: npt.ArrayLike) -> np.ndarray:
    """balance x intensity x turning of one step.

    Args:
        readings: (B, >=6) float32 readings (leading axes allowed, as in fitness_factors).
        power: (B,) commanded power.

    Returns:
        (B,) float32 step fitness.
    """
    balance, intensity, turning = fitness_factors(readings, power)
    balance *= intensity
    balance *= turning
    return balance


class Episodes:
    """A batch of episodes, stepped one control step at a time (Gymnasium-like).

    ``world`` and ``noise`` may be replaced between steps; a change takes
    effect at the next reading.  Randomness comes from ``streams``: an int
    seed draws for the whole batch, a sequence gives each robot its own.
    """

    def __init__(self, world: World = World(), noise: NoiseModel = NoiseModel(),
                 task: Task = Task()) -> None:
        self.task = task
        self.noise = noise
        self.world = world
        self.step_index = 0
        self.readings: np.ndarray | None = None

    @property
    def world(self) -> World:
        return self._world

    @world.setter
    def world(self, world: World) -> None:
        self._world = world
        # bearing-major: a robot's 8 readings are one 32-byte row, one index per robot
        self._table = np.ascontiguousarray(world.light_table().T)
        # the unrounded table, made when a noise model asks for it
        self._levels: np.ndarray | None = None

    @property
    def robots(self) -> int:
        return self._bearing.size

    @property
    def done(self) -> bool:
        return self.step_index >= self.task.steps

    @property
    def bearing_deg(self) -> np.ndarray:
        """Lamp bearing in the robot frame, degrees, CCW positive, in [-180, 180)."""
        return to_degrees(self._bearing)

    def reset(self, seed: npt.ArrayLike, robots: int | None = None,
              bearing_deg: npt.ArrayLike | None = None) -> np.ndarray:
        """Start B episodes.

        Args:
            seed: an int (one generator for the batch) or B ints (one stream per robot).
            robots: B, when ``seed`` is an int.
            bearing_deg: start bearings (scalar or (B,)), default 0.

        Returns:
            The first (B, SENSORS) float32 readings.
        """
        robots = robots if robots is not None else np.size(seed)
        self._stream = streams.make_stream(seed, robots)
        start = np.zeros(robots) if bearing_deg is None else np.broadcast_to(bearing_deg, robots)
        self._bearing = to_tenths(start)
        self.step_index = 0
        self.readings = self._sense()
        return self.readings

    def step(self, direction: npt.ArrayLike, power: npt.ArrayLike) -> np.ndarray | None:
        """Apply one turn per robot.

        Args:
            direction: (B,) -1 (left) or +1 (right).
            power: (B,) 0..9.

        Returns:
            The next (B, SENSORS) readings, or None when the episode is over.
        """
        if self.done:
            raise RuntimeError('the episode is over; call reset()')
        self._bearing = turn(self._bearing, np.asarray(direction, np.int32),
                             np.asarray(power, np.int32), self.world)
        self.step_index += 1
        self.readings = None if self.done else self._sense()
        return self.readings

    def _sense(self) -> np.ndarray:
        draws = self._stream.draw(self.step_index, streams.GROUP.start + len(self.noise.groups))
        if self.step_index % self.task.perturb_every == 0 and self.task.perturbation_deg > 0:
            self._bearing = self._bearing + self._knocked(
                knock_tenths(draws[streams.PERTURB], self.task))
        if self.step_index % WRAP_EVERY == 0:
            self._bearing %= TENTHS
        # 'wrap' costs a compare per robot where a modulo every step cost a division
        rows = np.take(self._light_table(), self._bearing, axis=0, mode='wrap')
        # The hot path's one change of orientation.  The look-up gives each robot's 8
        # readings as a row; the noise, the network and the fitness work sensor by sensor,
        # so the readings are laid out sensor-major once, here, and handed out as a
        # (B, SENSORS) view of that memory: each sensor's values for the whole batch stay
        # one contiguous row, and no caller transposes.
        base = np.empty(rows.shape[::-1], rows.dtype)
        base[...] = rows.T
        readings: np.ndarray = self.noise.apply(base, draws[streams.SENSOR], draws[streams.GROUP],
                                                out=base).T
        return readings

    def _knocked(self, tenths: np.ndarray) -> np.ndarray:
        """The knock the robot makes of a drawn one (here: as drawn)."""
        return tenths

    def _light_table(self) -> np.ndarray:
        """The integer table, or the light levels when the noise rounds the reading."""
        if getattr(self.noise, 'rounding', 'level') != 'reading':
            return self._table
        if self._levels is None:
            self._levels = np.ascontiguousarray(self.world.light_table(rounded=False).T)
        return self._levels


@dataclass
class Trace:
    """Per-step record of a batch of episodes; arrays are (steps, B, ...)."""

    bearing_deg: np.ndarray
    readings: np.ndarray
    direction: np.ndarray
    power: np.ndarray
    fitness: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.fitness = step_fitness(self.readings, self.power)


@overload
def run(policy: Policy, seed: npt.ArrayLike, robots: int | None = None, world: World = ...,
        noise: NoiseModel = ..., task: Task = ..., trace: Literal[False] = False) -> np.ndarray:
    ...


@overload
def run(policy: Policy, seed: npt.ArrayLike, robots: int | None = None, world: World = ...,
        noise: NoiseModel = ..., task: Task = ..., *, trace: Literal[True]) -> Trace:
    ...


@overload
def run(policy: Policy, seed: npt.ArrayLike, robots: int | None = None, world: World = ...,
        noise: NoiseModel = ..., task: Task = ..., trace: bool = False) -> np.ndarray | Trace:
    ...


def run(policy: Policy, seed: npt.ArrayLike, robots: int | None = None, world: World = World(),
        noise: NoiseModel = NoiseModel(), task: Task = Task(),
        trace: bool = False) -> np.ndarray | Trace:
    """Run B episodes under ``policy``.

    Args:
        policy: (B, SENSORS) readings -> (direction (B,), power (B,)).
        seed, robots: as for ``Episodes.reset``.
        world, noise, task: the episode's setting.
        trace: return the per-step record instead of the fitness.

    Returns:
        (B,) float32 fitness, the mean step fitness summed step by step; or a ``Trace``.
    """
    env = Episodes(world, noise, task)
    readings: np.ndarray | None = env.reset(seed, robots)
    total = np.zeros(env.robots, np.float32)
    rows: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
    while readings is not None:
        direction, power = policy(readings)
        total += step_fitness(readings, power)
        if trace:
            rows.append((env.bearing_deg, readings.copy(), direction, power))
        readings = env.step(direction, power)
    if trace:
        return Trace(*(np.stack(col) for col in zip(*rows)))
    return total / task.steps
