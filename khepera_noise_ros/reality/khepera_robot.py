"""The hardware bridge's backend: the light-centring episode on Kheperas.

``KheperaRobots`` has the interface of ``core.task.Episodes``, so the robot node runs
unchanged over it; its bodies are ``SerialRobots`` (one serial port per robot) or, without
a port, ``InProcessRobots`` over an ``EmulatedWorld``.
"""
from __future__ import annotations

import atexit
from typing import Protocol

import numpy as np

from ..core import streams
from ..core.khepera import DARK, World
from ..core.task import Task, knock_deg
from .serial_link import RobotUnreachable
from .serial_protocol import Wheels
from .serial_robots import TURN_MODES, SerialRobots
from .world import Condition, EmulatedWorld

__all__ = ['KheperaRobots', 'InProcessRobots', 'Robots', 'RobotUnreachable', 'SerialRobots',
           'TURN_MODES']


class Robots(Protocol):
    """The bodies an episode drives: ``capacity`` robots, the first B used at a time."""

    capacity: int

    def place(self, robots: int, condition: Condition, bearing_deg) -> None: ...

    def act(self, turns: list[np.ndarray], read: bool) -> np.ndarray | None:
        """Turn robot i by ``turns[k][i]`` pulses for each k in order, then, if ``read``,
        return the (B, 8) light readings.  One call, so that a link can send it at once."""

    @property
    def bearing_deg(self) -> np.ndarray | None: ...

    def stop(self) -> None: ...

    def close(self) -> None: ...


# --- the episode ---------------------------------------------------------------------

class KheperaRobots:
    """A batch of Kheperas behind the ``Episodes`` interface."""

    def __init__(self, bodies: Robots, world: World = World(), task: Task = Task(),
                 wheels: Wheels = Wheels()):
        """``wheels`` is the geometry the turns are computed with (the bridge's belief);
        ``world`` gives deg_per_power and the lighting condition declared to an emulator."""
        self.bodies, self.world, self.task, self.wheels = bodies, world, task, wheels
        self.step_index = 0
        self.failed = False
        self.readings: np.ndarray | None = None
        self.robots = 0
        self._residual = np.zeros(bodies.capacity)
        atexit.register(self.close)

    @classmethod
    def on_ports(cls, ports, world: World = World(), task: Task = Task(),
                 wheels: Wheels = Wheels(), **serial_options) -> 'KheperaRobots':
        """Robots on serial ports; ``serial_options`` go to ``SerialRobots``."""
        return cls(SerialRobots(ports, **serial_options), world, task, wheels)

    @property
    def done(self) -> bool:
        return self.failed or self.step_index >= self.task.steps

    @property
    def bearing_deg(self) -> np.ndarray | None:
        """Ground truth where the robots know it (an emulator); None on real robots."""
        return self.bodies.bearing_deg

    def reset(self, seed, robots: int | None = None, bearing_deg=None) -> np.ndarray:
        """Start B episodes on the first B robots; returns the first (8, B) readings."""
        robots = int(np.size(seed)) if robots is None else int(robots)
        if not 1 <= robots <= self.bodies.capacity:
            raise ValueError(f'{robots} robots asked for, but there are '
                             f'{self.bodies.capacity} (one per serial port)')
        self._stream = streams.make_stream(seed, robots)
        self.robots, self.step_index, self.failed = robots, 0, False
        self._residual[:] = 0.0
        condition = Condition(self.world.lamp_distance_mm, self.world.ambient)
        self._guarded(self.bodies.place, robots, condition, bearing_deg)
        self.readings = self._guarded(self._act, [])
        return self.readings

    def step(self, direction, power) -> np.ndarray | None:
        """Turn every robot, then read; None once the episode is over."""
        if self.done:
            raise RuntimeError('the episode is over; call reset()')
        direction, power = np.asarray(direction), np.asarray(power)
        if direction.shape != (self.robots,) or power.shape != (self.robots,):
            raise ValueError(f'direction and power must have {self.robots} values, got '
                             f'{direction.shape} and {power.shape}')
        turn = self._pulses(direction * power * self.world.deg_per_power)
        self.step_index += 1
        self.readings = self._guarded(self._act, [turn])
        return self.readings

    def close(self) -> None:
        """Stop the motors and release the robots (idempotent)."""
        atexit.unregister(self.close)
        self.bodies.close()

    def _guarded(self, action, *args):
        """Run ``action``; an unreachable robot fails the episode and the motors stop."""
        try:
            return action(*args)
        except RobotUnreachable:
            self.failed = True
            self.bodies.stop()
            raise

    def _act(self, turns: list[np.ndarray]) -> np.ndarray | None:
        """Make ``turns``; unless the episode is over, knock the heading on perturbation
        steps and read the light sensors."""
        if self.step_index >= self.task.steps:
            self.bodies.act(turns, read=False)
            return None
        draws = self._stream.draw(self.step_index)
        if self.step_index % self.task.perturb_every == 0 and self.task.perturbation_deg > 0:
            turns = turns + [self._pulses(knock_deg(draws[streams.PERTURB], self.task))]
        return np.minimum(self.bodies.act(turns, read=True), DARK).astype(np.float64)

    def _pulses(self, deg: np.ndarray) -> np.ndarray:
        """Whole wheel pulses that turn robot i by deg[i] degrees, positive to the right;
        the rounding is carried into the next turn."""
        wanted = np.asarray(deg, np.float64) + self._residual[:self.robots]
        pulses = np.rint(wanted / self.wheels.deg_per_pulse).astype(np.int64)
        self._residual[:self.robots] = wanted - pulses * self.wheels.deg_per_pulse
        return pulses


# --- robots in this process ------------------------------------------------------------

class InProcessRobots:
    """An EmulatedWorld's robots, driven directly: no serial port, no protocol.

    ``wheels`` is the emulated robots' true geometry, as the emulator's is.
    """

    def __init__(self, world: EmulatedWorld, wheels: Wheels = Wheels()):
        self.world, self.wheels = world, wheels
        self.capacity = world.robots
        self._active = np.arange(0)

    def place(self, robots: int, condition: Condition, bearing_deg) -> None:
        self._active = np.arange(robots)
        self.world.set_condition(condition, self._active)
        if bearing_deg is not None:
            self.world.set_bearing(np.broadcast_to(bearing_deg, robots), self._active)

    def act(self, turns: list[np.ndarray], read: bool) -> np.ndarray | None:
        for pulses in turns:
            moving = np.flatnonzero(pulses)
            if moving.size:
                self.world.turn(pulses[moving] * self.wheels.deg_per_pulse, moving)
        return self.world.read(self._active) if read else None

    @property
    def bearing_deg(self) -> np.ndarray:
        return self.world.bearing_deg[self._active]

    def stop(self) -> None:
        pass

    def close(self) -> None:
        pass
