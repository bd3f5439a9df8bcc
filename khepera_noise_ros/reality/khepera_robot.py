"""The hardware bridge's backend: the light-centring episode on Kheperas.

``KheperaRobots`` has the interface of the simulator's ``core.task.Episodes``
(``reset``/``step``, ``task``, ``bearing_deg``, ``done``), so the robot node
runs unchanged over it.  It runs the episode; the robots themselves are
``SerialRobots`` (one serial port per robot, a list of ports is a batch) or,
without any port, ``InProcessRobots`` over an ``EmulatedWorld``.  Both turn in
whole wheel pulses, so the same seeds give the same readings either way.

A turn of ``direction * power * deg_per_power`` degrees is made in place with
position control: zero the position counters (``G,0,0``), send the wheels to
opposite targets (``C,p,-p``; ``p > 0`` turns right) and read the counters
(``H``) until they arrive.  With a 53 mm wheel base and 0.08 mm per pulse a
degree is 5.78 pulses; the rounding left over is carried into the next turn.
``turn_mode='speed'`` instead sets opposite wheel speeds (``D``) for the time
the turn takes, then stops them.

Every ``perturb_every`` steps (step 0 included) the robot is turned by a random
angle drawn exactly as the simulator draws its heading knock, from the same
per-robot seed streams, so simulator and robot see the same knocks.

A timeout or a garbled or short reply is logged and the command sent again
(every command used is idempotent), at most ``retries`` times; a port that
fails is reopened.  When that does not help, ``RobotUnreachable`` is raised and
the robot node fails the episode.  ``close()`` stops the motors; it also runs
at interpreter exit.
"""
from __future__ import annotations

import atexit
import logging
import termios
import time
from dataclasses import dataclass
from typing import Callable, Protocol, TypeVar

import numpy as np
import serial

from ..core import streams
from ..core.khepera import DARK, World
from ..core.task import Task, knock_deg
from . import serial_protocol as sp
from .serial_protocol import Wheels
from .world import Condition, EmulatedWorld

T = TypeVar('T')
PORT_ERRORS = (serial.SerialException, OSError, termios.error)   # a device that went away
EMULATOR_PROTOCOL = 'emulator'      # the emulator's protocol version in its reply to B
TURN_MODES = ('position', 'speed')
POSITION_SPEED = 2000.0             # pulses/s, the Khepera's default position-mode top speed
ON_TARGET = 1                       # pulses from the target that count as arrived


class RobotUnreachable(RuntimeError):
    """A robot did not answer sensibly after every retry: the episode fails."""


class Robots(Protocol):
    """The bodies an episode drives: ``capacity`` robots, the first B used at a time."""

    capacity: int

    def place(self, robots: int, condition: Condition, bearing_deg) -> None: ...

    def turn(self, pulses: np.ndarray) -> None: ...

    def read(self) -> np.ndarray: ...

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
        self.readings = self._guarded(self._sense)
        return self.readings

    def step(self, direction, power) -> np.ndarray | None:
        """Turn every robot, then read; None once the episode is over."""
        if self.done:
            raise RuntimeError('the episode is over; call reset()')
        direction, power = np.asarray(direction), np.asarray(power)
        if direction.shape != (self.robots,) or power.shape != (self.robots,):
            raise ValueError(f'direction and power must have {self.robots} values, got '
                             f'{direction.shape} and {power.shape}')
        self._guarded(self._turn, direction * power * self.world.deg_per_power)
        self.step_index += 1
        self.readings = None if self.done else self._guarded(self._sense)
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

    def _sense(self) -> np.ndarray:
        """Knock the heading on perturbation steps, then read the light sensors."""
        draws = self._stream.draw(self.step_index)
        if self.step_index % self.task.perturb_every == 0 and self.task.perturbation_deg > 0:
            self._turn(knock_deg(draws[streams.PERTURB], self.task))
        return np.minimum(self.bodies.read(), DARK).astype(np.float64)

    def _turn(self, deg: np.ndarray) -> None:
        """Turn robot i by deg[i] degrees, positive to the right, in whole pulses."""
        wanted = np.asarray(deg, np.float64) + self._residual[:self.robots]
        pulses = np.rint(wanted / self.wheels.deg_per_pulse).astype(np.int64)
        self._residual[:self.robots] = wanted - pulses * self.wheels.deg_per_pulse
        self.bodies.turn(pulses)


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

    def turn(self, pulses: np.ndarray) -> None:
        moving = np.flatnonzero(pulses)
        if moving.size:
            self.world.turn(pulses[moving] * self.wheels.deg_per_pulse, moving)

    def read(self) -> np.ndarray:
        return self.world.read(self._active).T

    @property
    def bearing_deg(self) -> np.ndarray:
        return self.world.bearing_deg[self._active]

    def stop(self) -> None:
        pass

    def close(self) -> None:
        pass


# --- robots on serial ports --------------------------------------------------------------

@dataclass(frozen=True)
class LinkSettings:
    baudrate: int = 9600
    timeout_s: float = 0.5
    retries: int = 3

    def __post_init__(self):
        if self.baudrate not in serial.Serial.BAUDRATES:
            raise ValueError(f'baudrate must be a standard rate such as 9600, 19200 or 38400, '
                             f'got {self.baudrate!r}')
        if not 0.001 <= self.timeout_s <= 60:
            raise ValueError(f'timeout_s must be in [0.001, 60] s, got {self.timeout_s!r}')
        if not 0 <= self.retries <= 100:
            raise ValueError(f'retries must be in [0, 100], got {self.retries!r}')


class SerialLink:
    """One robot's port: send a command, read one reply line, retry when that fails."""

    def __init__(self, port: str, settings: LinkSettings, logger, name: str):
        self.port, self.settings, self.logger, self.name = port, settings, logger, name
        self.version: tuple[str, str] | None = None
        self.used = False
        self._serial: serial.Serial | None = None

    @property
    def emulated(self) -> bool:
        return self.version is not None and self.version[1] == EMULATOR_PROTOCOL

    def close(self) -> None:
        if self._serial is not None:
            try:
                self._serial.close()
            except PORT_ERRORS:
                pass
            self._serial = None

    def request(self, command: bytes, parse: Callable[[bytes], T]) -> T:
        """``parse`` of the reply to ``command``; RobotUnreachable when retries run out."""
        label = command.decode('ascii').strip()
        attempts = self.settings.retries + 1
        for attempt in range(1, attempts + 1):
            outcome = self._attempt(command, parse)
            if isinstance(outcome, tuple):
                return outcome[0]
            if attempt < attempts:
                self.logger.warning(f'{self.name}: {label!r}: {outcome}; retrying '
                                    f'({attempt}/{self.settings.retries})')
        message = f'{self.name} unreachable: {label!r} failed {attempts} times, last: {outcome}'
        self.logger.error(message)
        raise RobotUnreachable(message)

    def _attempt(self, command: bytes, parse) -> tuple | str:
        """(value,) on success, else what went wrong."""
        self.used = True
        try:
            if self._serial is None:
                self._serial = serial.Serial(self.port, self.settings.baudrate,
                                             timeout=self.settings.timeout_s,
                                             write_timeout=self.settings.timeout_s)
            self._serial.reset_input_buffer()
            self._serial.write(command)
            line = self._serial.read_until(b'\n')
        except PORT_ERRORS as exc:
            self.close()
            time.sleep(self.settings.timeout_s)       # give a device coming back a moment
            return f'serial port failed ({exc})'
        if not line.endswith(b'\n'):
            return f'no complete reply within {self.settings.timeout_s} s (got {line!r})'
        try:
            return (parse(line),)
        except sp.ProtocolError as exc:
            return f'garbled reply: {exc}'

    def ack(self, letter: str, *args) -> None:
        """A command whose reply is only its lower-case letter."""
        self.request(sp.format_command(letter, *args), lambda line: sp.parse_reply(line, letter))

    def values(self, letter: str) -> tuple[int, ...]:
        return self.request(sp.format_command(letter), lambda line: sp.parse_reply(line, letter))

    def z(self, sub: str, *args) -> tuple[float, ...]:
        """An emulator extension command (never sent to a real robot)."""
        return self.request(sp.format_command('Z', sub, *args),
                            lambda line: sp.parse_z_reply(line, sub))

    def identify(self) -> tuple[str, str]:
        if self.version is None:
            self.version = self.request(sp.format_command('B'), sp.parse_version)
            self.logger.info(f'{self.name}: Khepera BIOS {self.version[0]}, protocol '
                             f'{self.version[1]}')
        return self.version

    def stop_motors(self) -> bool:
        """One try at 'D,0,0' that never raises; True if the robot confirmed."""
        return isinstance(self._attempt(sp.format_command('D', 0, 0),
                                        lambda line: sp.parse_reply(line, 'D')), tuple)


class SerialRobots:
    """Kheperas on serial ports, spoken to in their own protocol.

    An emulator (it answers B with protocol ``emulator``) is also told the
    lighting condition and start bearings, and asked for the true bearing; on
    a real robot the experimenter arranges those by hand and the bearing is
    unknown.
    """

    def __init__(self, ports, baudrate: int = 9600, timeout_s: float = 0.5, retries: int = 3,
                 turn_mode: str = 'position', turn_speed: int = 20, logger=None):
        ports = [str(p) for p in ports]
        if not ports:
            raise ValueError('ports must name at least one serial port, e.g. /dev/ttyUSB0')
        if turn_mode not in TURN_MODES:
            raise ValueError(f'turn_mode must be one of {TURN_MODES}, got {turn_mode!r}')
        if not 1 <= turn_speed <= sp.SPEED_MAX:
            raise ValueError(f'turn_speed must be in [1, {sp.SPEED_MAX}] pulses/10 ms, '
                             f'got {turn_speed!r}')
        settings = LinkSettings(baudrate, timeout_s, retries)
        self.logger = logger if logger is not None else logging.getLogger(__name__)
        self.links = [SerialLink(p, settings, self.logger, f'robot {i} ({p})')
                      for i, p in enumerate(ports)]
        self.capacity = len(self.links)
        self.turn_mode, self.turn_speed = turn_mode, turn_speed
        self._active: list[SerialLink] = []
        self._bearing: np.ndarray | None = None
        self._warned_by_hand = False

    @property
    def emulated(self) -> bool:
        return bool(self._active) and all(link.emulated for link in self._active)

    @property
    def bearing_deg(self) -> np.ndarray | None:
        return self._bearing

    def place(self, robots: int, condition: Condition, bearing_deg) -> None:
        self._active = self.links[:robots]
        for link in self._active:
            link.identify()
        if self.emulated:
            for link in self._active:
                link.z(sp.Z_LIGHT, condition.lamp_distance_mm, condition.ambient)
            if bearing_deg is not None:
                for link, deg in zip(self._active, np.broadcast_to(bearing_deg, robots)):
                    link.z(sp.Z_BEARING, float(deg))
        elif bearing_deg is not None and not self._warned_by_hand:
            self._warned_by_hand = True
            self.logger.warning('start bearings are ignored: on a real robot the experimenter '
                                'sets the heading by hand')

    def read(self) -> np.ndarray:
        readings = np.stack([link.values('O') for link in self._active], axis=1)
        self._bearing = np.array([link.z(sp.Z_READ_BEARING)[0] for link in self._active]) \
            if self.emulated else None
        return readings

    def turn(self, pulses: np.ndarray) -> None:
        moving = [(link, int(p)) for link, p in zip(self._active, pulses) if p != 0]
        if self.turn_mode == 'position':
            self._turn_to_positions(moving)
        else:
            self._turn_at_speed(moving)

    def _turn_to_positions(self, moving: list[tuple[SerialLink, int]]) -> None:
        for link, p in moving:
            link.ack('G', 0, 0)
        for link, p in moving:
            link.ack('C', p, -p)
        for link, p in moving:
            self._wait_on_target(link, p)

    def _wait_on_target(self, link: SerialLink, p: int) -> None:
        deadline = time.monotonic() + abs(p) / POSITION_SPEED + 2 * link.settings.timeout_s
        while True:
            left, right = link.values('H')
            if abs(left - p) <= ON_TARGET and abs(right + p) <= ON_TARGET:
                return
            if time.monotonic() > deadline:
                self.logger.warning(f'{link.name}: wheels at ({left}, {right}) did not reach '
                                    f'({p}, {-p}); is the robot blocked?')
                return
            time.sleep(0.01)

    def _turn_at_speed(self, moving: list[tuple[SerialLink, int]]) -> None:
        speed = self.turn_speed
        start = time.monotonic()
        for link, p in moving:
            link.ack('D', speed * np.sign(p), -speed * np.sign(p))
        for link, p in sorted(moving, key=lambda m: abs(m[1])):
            time.sleep(max(0.0, start + abs(p) / (speed * 100.0) - time.monotonic()))
            link.ack('D', 0, 0)

    def stop(self) -> None:
        """Best effort, after a failure: one 'D,0,0' to every robot in the episode."""
        for link in self._active:
            link.stop_motors()

    def close(self) -> None:
        """Stop every motor that was ever driven, then close the ports (idempotent)."""
        for link in self.links:
            if link.used and not link.stop_motors():
                self.logger.error(f'{link.name}: could not confirm that the motors stopped')
            link.close()
            link.used = False
