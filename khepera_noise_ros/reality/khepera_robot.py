"""The hardware bridge's backend: the light-centring episode on Kheperas.

``KheperaRobots`` has the interface of the simulator's ``core.task.Episodes``
(``reset``/``step``, ``task``, ``bearing_deg``, ``done``), so the robot node
runs unchanged over it.  It runs the episode; the robots themselves are
``SerialRobots`` (one serial port per robot, a list of ports is a batch) or,
without any port, ``InProcessRobots`` over an ``EmulatedWorld``.  Both turn in
whole wheel pulses, so the same seeds give the same readings either way.

A turn of ``direction * power * deg_per_power`` degrees is made in place with
position control: the wheels are sent to targets ``p`` pulses on from where
they are (``C``; ``p > 0`` turns right), from counters zeroed (``G,0,0``) when
the episode starts, and the counters are read (``H``) until they arrive.  With
a 53 mm wheel base and 0.08 mm per pulse a degree is 5.78 pulses; the rounding
left over is carried into the next turn.  ``turn_mode='speed'`` instead sets
opposite wheel speeds (``D``) for the time the turn takes, then stops them.

Every ``perturb_every`` steps (step 0 included) the robot is turned by a random
angle drawn exactly as the simulator draws its heading knock, from the same
per-robot seed streams, so simulator and robot see the same knocks.

The robots of a batch are spoken to at once: a command goes to every port
before any reply is awaited, so a step costs one round trip, not one per
robot.  An emulator (it names protocol ``emulator`` in its reply to ``B``)
finishes a move before it replies, so it is not polled, and the commands of a
step go to it in one write.

A timeout or a garbled or short reply is logged and the command sent again
(every command used is idempotent), at most ``retries`` times; a port that
fails is reopened.  When that does not help, ``RobotUnreachable`` is raised and
the robot node fails the episode.  ``close()`` stops the motors; it also runs
at interpreter exit.
"""
from __future__ import annotations

import atexit
import functools
import logging
import math
import os
import select
import termios
import time
from dataclasses import dataclass
from typing import Any, Callable, Protocol

import numpy as np
import serial

from ..core import streams
from ..core.khepera import DARK, World
from ..core.task import Task, knock_deg
from . import serial_protocol as sp
from .serial_protocol import Wheels
from .world import Condition, EmulatedWorld

PORT_ERRORS = (serial.SerialException, OSError, termios.error)   # a device that went away
EMULATOR_PROTOCOL = 'emulator'      # the emulator's protocol version in its reply to B
TURN_MODES = ('position', 'speed')
POSITION_SPEED = 2000.0             # pulses/s, the Khepera's default position-mode top speed
ON_TARGET = 1                       # pulses from the target that count as arrived
REZERO_PULSES = sp.POSITION_MAX // 2    # counters re-zeroed before a target gets this far


class RobotUnreachable(RuntimeError):
    """A robot did not answer sensibly after every retry: the episode fails."""


class Robots(Protocol):
    """The bodies an episode drives: ``capacity`` robots, the first B used at a time."""

    capacity: int

    def place(self, robots: int, condition: Condition, bearing_deg) -> None: ...

    def act(self, turns: list[np.ndarray], read: bool) -> np.ndarray | None:
        """Turn robot i by ``turns[k][i]`` pulses for each k in order, then, if ``read``,
        return the (8, B) light readings.  One call, so that a link can send it at once."""

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
        return self.world.read(self._active).T if read else None

    @property
    def bearing_deg(self) -> np.ndarray:
        return self.world.bearing_deg[self._active]

    def stop(self) -> None:
        pass

    def close(self) -> None:
        pass


# --- one robot's serial port ---------------------------------------------------------------

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


@dataclass(frozen=True)
class Request:
    """A command line and how to parse its reply (ProtocolError if it is not one).

    A ``target`` request sends the wheels to absolute positions: a later one to
    the same robot makes it moot, so it is not sent again when that one follows.
    """

    command: bytes
    parse: Callable[[bytes], Any]
    target: bool = False

    @property
    def label(self) -> str:
        return self.command.decode('ascii').strip()


def request(letter: str, *args) -> Request:
    """A standard command; its reply is the lower-case letter and integer values."""
    return Request(sp.format_command(letter, *args), functools.partial(sp.parse_reply,
                                                                       letter=letter))


def z_request(sub: str, *args) -> Request:
    """An emulator extension command (never sent to a real robot)."""
    return Request(sp.format_command('Z', sub, *args), functools.partial(sp.parse_z_reply,
                                                                         sub=sub))


IDENTIFY = Request(sp.format_command('B'), sp.parse_version)
READ_LIGHT = request('O')
READ_COUNTERS = request('H')
READ_BEARING = z_request(sp.Z_READ_BEARING)
ZERO_COUNTERS = request('G', 0, 0)
STOP_MOTORS = request('D', 0, 0)
PARSE_C = functools.partial(sp.parse_reply, letter='C')


class SerialLink:
    """One robot's port, opened on first use: it writes commands and hands back what
    arrives; ``exchange`` pairs replies with commands and retries."""

    def __init__(self, port: str, settings: LinkSettings, logger, name: str):
        self.port, self.settings, self.logger, self.name = port, settings, logger, name
        self.version: tuple[str, str] | None = None
        self.used = False
        self.counters = (0, 0)          # where the position counters are (or are headed)
        self.stale = False              # a reply may be left over: flush before writing
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

    def send(self, data: bytes) -> str | None:
        """Write ``data``; what went wrong, or None."""
        self.used = True
        try:
            if self._serial is None:        # opening also empties the input buffer
                self._serial = serial.Serial(self.port, self.settings.baudrate,
                                             timeout=self.settings.timeout_s,
                                             write_timeout=self.settings.timeout_s)
            elif self.stale:
                self._drain()
            self.stale = False
            self._write(data)
        except PORT_ERRORS as exc:
            self.close()
            return f'serial port failed ({exc})'
        return None

    def _drain(self) -> None:
        """Resynchronise after an exchange went wrong.  A reply still on its way would be
        read as the answer to the next command and shift every reply after it, so send
        B and throw away everything before its (unmistakable) reply."""
        self._serial.reset_input_buffer()
        self._write(IDENTIFY.command)
        deadline, pending = time.monotonic() + self.settings.timeout_s, b''
        while (left := deadline - time.monotonic()) > 0:
            if not select.select([self.fileno()], [], [], left)[0]:
                return
            pending += self.receive()
            *lines, pending = pending.split(b'\n')
            for line in lines:
                try:
                    IDENTIFY.parse(line + b'\n')
                    return
                except sp.ProtocolError:
                    continue        # a late reply to a command that was given up on

    def _write(self, data: bytes) -> None:
        try:
            sent = os.write(self.fileno(), data)        # all at once, as a rule
        except BlockingIOError:
            sent = 0
        if sent < len(data):
            self._serial.write(data[sent:])             # waits, up to write_timeout

    def fileno(self) -> int:
        return self._serial.fileno()

    def receive(self) -> bytes:
        """What has arrived, once ``fileno()`` polled readable; PORT_ERRORS if the device
        is gone (pyserial keeps the descriptor non-blocking)."""
        try:
            data = os.read(self.fileno(), 4096)
        except BlockingIOError:
            return b''
        if not data:
            raise serial.SerialException('the device reports data but returns none '
                                         '(disconnected?)')
        return data

    def ack(self, letter: str, *args) -> None:
        """Send one command whose reply is only its lower-case letter (by hand)."""
        exchange({self: [request(letter, *args)]})

    def identified(self, version: tuple[str, str]) -> None:
        self.version = version
        self.logger.info(f'{self.name}: Khepera BIOS {version[0]}, protocol {version[1]}')


# --- talking to many ports at once ----------------------------------------------------------

class Replies:
    """The reply lines of one link, matched in order to the requests it was sent.

    A line that is no reply to the next request but to a later one means the
    replies between were lost; a line that is no reply to any is garbled.
    """

    def __init__(self, requests: list[Request]):
        self.requests = requests
        self.outcomes: list[tuple | str] = []       # (value,) or what went wrong
        self.pending = b''

    @property
    def complete(self) -> bool:
        return len(self.outcomes) == len(self.requests)

    def feed(self, data: bytes) -> bool:
        """Take ``data``; True once every request has its outcome."""
        self.pending += data
        while not self.complete:
            end = self.pending.find(b'\n') + 1
            if not end:
                break
            line, self.pending = self.pending[:end], self.pending[end:]
            self._match(line)
        return self.complete

    def _match(self, line: bytes) -> None:
        first, errors = len(self.outcomes), []
        for j in range(first, len(self.requests)):
            try:
                value = self.requests[j].parse(line)
            except sp.ProtocolError as exc:
                errors.append(exc)
                continue
            self.outcomes += ['no complete reply (a later reply came first)'] * (j - first)
            self.outcomes.append((value,))
            return
        self.outcomes.append(f'garbled reply: {errors[0]}')

    def fail(self, reason: str) -> list[tuple | str]:
        """The outcomes, every request still unanswered failing with ``reason``."""
        return self.outcomes + [reason] * (len(self.requests) - len(self.outcomes))


def attempt(scripts: dict[SerialLink, list[Request]]) -> dict[SerialLink, list[tuple | str]]:
    """One try of every link's requests: each link's commands in one write, then every
    reply read as it comes, until all are in or the timeout; an outcome per request."""
    outcomes, replies, port_failed = {}, {}, False
    for link, requests in scripts.items():
        error = link.send(b''.join(r.command for r in requests))
        if error is None:
            replies[link] = Replies(requests)
        else:
            outcomes[link], port_failed = [error] * len(requests), True
    timeout = max(link.settings.timeout_s for link in scripts)
    by_fd, poller = {link.fileno(): link for link in replies}, select.poll()
    for fd in by_fd:
        poller.register(fd, select.POLLIN)
    deadline = time.monotonic() + timeout
    while by_fd:
        left = max(0.0, deadline - time.monotonic())
        for fd, _ in poller.poll(math.ceil(left * 1000)):
            link = by_fd[fd]
            try:
                done = replies[link].feed(link.receive())
            except PORT_ERRORS as exc:
                link.close()
                outcomes[link] = replies.pop(link).fail(f'serial port failed ({exc})')
                done = port_failed = True
            if done:
                poller.unregister(fd)
                del by_fd[fd]
        if not left:                # a reply already there is taken, however late we look
            break
    for link, pending in replies.items():
        outcomes[link] = pending.fail(f'no complete reply within {timeout} s '
                                      f'(got {pending.pending!r})')
        # anything unexpected: a late reply may still come, so flush before the next write
        link.stale = bool(pending.pending) or any(isinstance(o, str) for o in outcomes[link])
    if port_failed:
        time.sleep(timeout)         # give a device coming back a moment
    return outcomes


def exchange(scripts: dict[SerialLink, list[Request]]) -> dict[SerialLink, list]:
    """The parsed reply to every request, sending failed ones again (in order) up to
    ``retries`` times; RobotUnreachable names the first link that ran out."""
    results = {link: [None] * len(requests) for link, requests in scripts.items()}
    todo = {link: list(range(len(requests))) for link, requests in scripts.items() if requests}
    failures: dict[tuple[SerialLink, int], int] = {}
    while todo:
        outcomes = attempt({link: [scripts[link][i] for i in todo[link]] for link in todo})
        again, lost = {}, []
        for link, indices in todo.items():
            for i, outcome in zip(indices, outcomes[link]):
                if isinstance(outcome, tuple):
                    results[link][i] = outcome[0]
                    continue
                count = failures[link, i] = failures.get((link, i), 0) + 1
                label = scripts[link][i].label
                if scripts[link][i].target and any(r.target for r in scripts[link][i + 1:]):
                    link.logger.warning(f'{link.name}: {label!r}: {outcome}; not sent again: '
                                        f'the next move supersedes it')
                elif count <= link.settings.retries:
                    link.logger.warning(f'{link.name}: {label!r}: {outcome}; retrying '
                                        f'({count}/{link.settings.retries})')
                    again.setdefault(link, []).append(i)
                else:
                    lost.append((link, f'{link.name} unreachable: {label!r} failed {count} '
                                       f'times, last: {outcome}'))
        for link, message in lost:
            link.logger.error(message)
        if lost:
            raise RobotUnreachable(lost[0][1])
        todo = again
    return results


def stop_motors(links: list[SerialLink]) -> list[SerialLink]:
    """One try at 'D,0,0' on every link, never raising; the links that did not confirm."""
    if not links:
        return []
    outcomes = attempt({link: [STOP_MOTORS] for link in links})
    return [link for link in links if not isinstance(outcomes[link][0], tuple)]


# --- robots on serial ports --------------------------------------------------------------

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
        unknown = [link for link in self._active if link.version is None]
        for link, (version,) in exchange({link: [IDENTIFY] for link in unknown}).items():
            link.identified(version)
        scripts = {link: [] for link in self._active}
        if self.turn_mode == 'position':
            for link in self._active:
                scripts[link].append(ZERO_COUNTERS)
                link.counters = (0, 0)
        if self.emulated:
            light = z_request(sp.Z_LIGHT, condition.lamp_distance_mm, condition.ambient)
            starts = [None] * robots if bearing_deg is None \
                else np.broadcast_to(bearing_deg, robots)
            for link, deg in zip(self._active, starts):
                scripts[link].append(light)
                if deg is not None:
                    scripts[link].append(z_request(sp.Z_BEARING, float(deg)))
        elif bearing_deg is not None and not self._warned_by_hand:
            self._warned_by_hand = True
            self.logger.warning('start bearings are ignored: on a real robot the experimenter '
                                'sets the heading by hand')
        exchange(scripts)

    def act(self, turns: list[np.ndarray], read: bool) -> np.ndarray | None:
        if self.turn_mode == 'position' and self.emulated:
            # its moves are over when it replies: all go with the read, in one exchange, and
            # still robots' too, so that the emulator sees the whole batch every time
            scripts = self._aim([dict(zip(self._active, map(int, pulses))) for pulses in turns])
            if read:
                return self._read(scripts)
            exchange(scripts)
            return None
        for pulses in turns:
            move = {link: int(p) for link, p in zip(self._active, pulses) if p != 0}
            if self.turn_mode == 'speed':
                self._turn_at_speed(move)
            else:
                self._turn_to_positions(move)
        return self._read({}) if read else None

    def _read(self, scripts: dict[SerialLink, list[Request]]) -> np.ndarray:
        """Send ``scripts`` with the light readings (and true bearing) of every robot."""
        asks = [READ_LIGHT, READ_BEARING] if self.emulated else [READ_LIGHT]
        scripts = {link: scripts.get(link, []) + asks for link in self._active}
        replies = exchange(scripts)
        self._bearing = np.array([replies[link][-1][0] for link in self._active]) \
            if self.emulated else None
        return np.array([replies[link][len(scripts[link]) - len(asks)]
                         for link in self._active]).T

    def _aim(self, moves: list[dict[SerialLink, int]]) -> dict[SerialLink, list[Request]]:
        """C commands making ``moves`` one after the other, each sending a robot's wheels
        ``p`` pulses on and ``-p`` back; counters that could run out of range are zeroed
        first, in an exchange of their own."""
        links = {link: sum(abs(move.get(link, 0)) for move in moves)
                 for move in moves for link in move}
        far = [link for link, travel in links.items()
               if max(map(abs, link.counters)) + travel > REZERO_PULSES]
        if far:
            exchange({link: [ZERO_COUNTERS] for link in far})
            for link in far:
                link.counters = (0, 0)
        scripts: dict[SerialLink, list[Request]] = {}
        for move in moves:
            for link, p in move.items():
                link.counters = (link.counters[0] + p, link.counters[1] - p)
                scripts.setdefault(link, []).append(
                    Request(sp.format_command('C', *link.counters), PARSE_C, target=True))
        return scripts

    def _turn_to_positions(self, move: dict[SerialLink, int]) -> None:
        """A real robot's move: send it, then read the counters until the wheels arrive."""
        start = time.monotonic()
        exchange(self._aim([move]))
        targets = {link: link.counters for link in move}
        deadlines = {link: start + abs(p) / POSITION_SPEED + 2 * link.settings.timeout_s
                     for link, p in move.items()}
        while targets:
            counters = exchange({link: [READ_COUNTERS] for link in targets})
            now = time.monotonic()
            for link, ((left, right),) in counters.items():
                link.counters = (left, right)       # the next move starts from here
                aim = targets[link]
                if abs(left - aim[0]) <= ON_TARGET and abs(right - aim[1]) <= ON_TARGET:
                    del targets[link]
                elif now > deadlines[link]:
                    self.logger.warning(f'{link.name}: wheels at ({left}, {right}) did not '
                                        f'reach {aim}; is the robot blocked?')
                    del targets[link]
            if targets:
                time.sleep(0.01)

    def _turn_at_speed(self, move: dict[SerialLink, int]) -> None:
        """Opposite wheel speeds for the time each turn takes, then stop."""
        speed = self.turn_speed
        start = time.monotonic()
        exchange({link: [request('D', speed * np.sign(p), -speed * np.sign(p))]
                  for link, p in move.items()})
        due = sorted((start + abs(p) / (speed * 100.0), i, link)
                     for i, (link, p) in enumerate(move.items()))
        while due:
            time.sleep(max(0.0, due[0][0] - time.monotonic()))
            now = time.monotonic()
            stopping = [link for t, _, link in due if t <= now]
            due = due[len(stopping):]
            exchange({link: [STOP_MOTORS] for link in stopping})

    def stop(self) -> None:
        """Best effort, after a failure: one 'D,0,0' to every robot in the episode."""
        stop_motors(self._active)

    def close(self) -> None:
        """Stop every motor that was ever driven, then close the ports (idempotent)."""
        for link in stop_motors([link for link in self.links if link.used]):
            self.logger.error(f'{link.name}: could not confirm that the motors stopped')
        for link in self.links:
            link.close()
            link.used = False
