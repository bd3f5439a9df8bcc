"""The robot emulator: an EmulatedWorld's robots on pseudo-terminals, one per robot.

Each robot answers the Khepera serial protocol (``serial_protocol``) on its own
pty, so the hardware bridge and any serial tool talk to it as to a robot on a
serial cable.  Time is virtual: a position move (``C``) completes at once, and
one ``O`` is one sample period of the world.  Wheel speeds set with ``D`` do
turn the robot in wall-clock time, as on a real robot.  Translation is ignored:
the emulated robot stands at a fixed position, as in the paper's task.

Besides the robot's commands it answers ``Z``, the experimenter's extension:
``Z,L,<lamp_distance_mm>,<ambient>`` sets the lighting condition,
``Z,B,<deg>`` puts the lamp at a bearing and ``Z,R`` reports the true bearing.
Its answer to ``B`` names protocol ``emulator``, which is how a bridge knows it
may use them, and that a move is over when ``C`` is answered.  A line it cannot
execute is answered ``?,<reason>``.

Commands are answered in the order each robot sent them, and all robots'
commands waiting at one time together: the n-th line of every robot is one
round, whose light readings and turns are one call to the world (a robot's
readings depend only on its own commands, so this changes no value).  A
robot's replies go back in one write.

``inject`` makes the next replies of a robot fail (silent, garbled or short)
and ``unplug`` makes its device disappear, to exercise a bridge's fault
handling; ``fault_rate`` does the former at random.
"""
from __future__ import annotations

import os
import selectors
import threading
import time
import tty
from collections import Counter, deque

import numpy as np

from . import serial_protocol as sp
from .world import Condition, EmulatedWorld

VERSION = ('5.02', 'emulator')
READ_BEARING = sp.Command('Z', (sp.Z_READ_BEARING,))
FAULTS = ('silent', 'garbled', 'short')
GATHER_S = 0.002                # longest wait for the rest of a batch of commands


class _Robot:
    """One robot's wheels and line buffer; its light and heading live in the world."""

    def __init__(self, index: int):
        self.index = index
        self.buffer = b''
        self.lines: deque[bytes] = deque()      # commands received, not yet answered
        self.counters = np.zeros(2)             # position counters, pulses (fractional)
        self.speeds = np.zeros(2)               # pulses per 10 ms
        self.since = time.monotonic()
        self.faults: deque[str] = deque()
        self.served: Counter = Counter()
        self.master = -1
        self.slave = -1
        self.port = ''


class Emulator:
    """Serves ``world``'s robots until ``stop()``; use as a context manager."""

    def __init__(self, world: EmulatedWorld, wheels: sp.Wheels = sp.Wheels(),
                 fault_rate: float = 0.0, seed: int = 0):
        if not 0.0 <= fault_rate <= 1.0:
            raise ValueError(f'fault_rate must be in [0, 1], got {fault_rate!r}')
        self.world, self.wheels, self.fault_rate = world, wheels, fault_rate
        self._rng = np.random.default_rng(seed)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._wake_r, self._wake_w = os.pipe()
        self._unplugged: set[int] = set()
        self._thread: threading.Thread | None = None
        self._expected: set[_Robot] = set()     # the robots answered together last time
        self.robots = [self._open_pty(_Robot(i)) for i in range(world.robots)]

    @staticmethod
    def _open_pty(robot: _Robot) -> _Robot:
        robot.master, robot.slave = os.openpty()
        tty.setraw(robot.slave)                  # no echo, no line editing, bytes as sent
        os.set_blocking(robot.master, False)
        robot.port = os.ttyname(robot.slave)
        return robot

    @property
    def ports(self) -> list[str]:
        """Device paths, one per robot, to open as serial ports."""
        return [r.port for r in self.robots]

    def served(self, robot: int) -> Counter:
        """Commands answered so far by ``robot``, by letter."""
        with self._lock:
            return Counter(self.robots[robot].served)

    def inject(self, robot: int, fault: str, count: int = 1) -> None:
        """Make the next ``count`` replies of ``robot`` fail with ``fault``."""
        if fault not in FAULTS:
            raise ValueError(f'fault must be one of {FAULTS}, got {fault!r}')
        with self._lock:
            self.robots[robot].faults.extend([fault] * count)

    def unplug(self, robot: int) -> None:
        """The robot's device disappears, as when its cable is pulled."""
        with self._lock:
            self._unplugged.add(robot)
        os.write(self._wake_w, b'u')

    # --- running ----------------------------------------------------------------------

    def start(self) -> 'Emulator':
        self._thread = threading.Thread(target=self.serve, name='khepera-emulator',
                                        daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop serving and remove the devices; safe to call twice."""
        self._stop.set()
        try:
            os.write(self._wake_w, b's')
        except OSError:
            pass
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        self._close_all()

    def __enter__(self) -> 'Emulator':
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def serve(self) -> None:
        """Answer commands until stop(); runs in the calling thread."""
        with selectors.DefaultSelector() as selector:
            selector.register(self._wake_r, selectors.EVENT_READ, None)
            for robot in self.robots:
                selector.register(robot.master, selectors.EVENT_READ, robot)
            while not self._stop.is_set():
                ready = [key.data for key, _ in selector.select(timeout=0.5)]
                if None in ready:
                    os.read(self._wake_r, 64)
                    self._unplug_pending(selector)
                heard = [robot for robot in ready if isinstance(robot, _Robot)
                         and self._receive(robot, selector)]
                self._answer_waiting(self._gather(heard, selector))

    def _unplug_pending(self, selector) -> None:
        with self._lock:
            pending, self._unplugged = self._unplugged, set()
        for i in pending:
            robot = self.robots[i]
            if robot.master >= 0:
                selector.unregister(robot.master)
                self._close_robot(robot)

    def _receive(self, robot: _Robot, selector) -> bool:
        """Read what ``robot``'s host sent; True if it holds complete command lines."""
        if robot.master < 0:                     # unplugged earlier in this round
            return False
        try:
            data = os.read(robot.master, 4096)
        except BlockingIOError:
            return False
        except OSError:
            data = b''
        if not data:                             # the device is gone
            selector.unregister(robot.master)
            self._close_robot(robot)
            return False
        robot.buffer += data.replace(b'\n', b'\r')
        *lines, robot.buffer = robot.buffer.split(b'\r')
        robot.lines.extend(line for line in lines if line)
        return bool(robot.lines)

    def _gather(self, heard: list[_Robot], selector) -> list[_Robot]:
        """``heard`` and the robots that join them shortly: a host that drives several
        robots writes to them one after the other, and the robots answered together last
        time are expected together again, for at most ``GATHER_S``."""
        if not heard:
            return heard
        deadline = time.monotonic() + GATHER_S
        while not self._expected <= set(heard):
            left = deadline - time.monotonic()
            ready = [key.data for key, _ in selector.select(timeout=left)] if left > 0 else []
            if not ready or not all(isinstance(robot, _Robot) for robot in ready):
                break                       # time is up, or the loop has other work
            for robot in ready:
                if self._receive(robot, selector) and robot not in heard:
                    heard.append(robot)
        self._expected = set(heard)
        return heard

    def _answer_waiting(self, robots: list[_Robot]) -> None:
        """Answer every waiting line of ``robots``, a round at a time; one write each."""
        replies: dict[_Robot, list[bytes]] = {robot: [] for robot in robots}
        while robots:
            round_ = [(robot, robot.lines.popleft()) for robot in robots]
            for (robot, _), reply in zip(round_, self._answer_round(round_)):
                replies[robot].append(self._faulty(robot, reply))
            robots = [robot for robot in robots if robot.lines]
        for robot, lines in replies.items():
            try:
                os.write(robot.master, b''.join(lines))
            except OSError:                      # nobody reads, or the device is gone
                pass

    def _faulty(self, robot: _Robot, reply: bytes) -> bytes:
        """``reply`` as it reaches the host: lost, garbled or cut short by a fault."""
        with self._lock:
            fault = robot.faults.popleft() if robot.faults else None
        if fault is None and self.fault_rate and self._rng.random() < self.fault_rate:
            fault = FAULTS[self._rng.integers(len(FAULTS))]
        if fault == 'silent':
            return b''
        body = bytearray(reply[:-len(sp.LINE_END)])
        if fault == 'garbled':                   # one byte in the middle corrupted
            body[len(body) // 2] = ord('~')
            return bytes(body) + sp.LINE_END
        if fault == 'short':                     # the second half lost
            return bytes(body[:len(body) // 2]) + sp.LINE_END
        return reply

    # --- the protocol -------------------------------------------------------------------

    def answer(self, index: int, line: bytes) -> bytes:
        """The reply of robot ``index`` to one command line."""
        return self._answer_round([(self.robots[index], line)])[0]

    def _answer_round(self, round_: list[tuple[_Robot, bytes]]) -> list[bytes]:
        """Replies to one line each of distinct robots; their reads and position moves
        are one call to the world each."""
        commands = []
        for robot, line in round_:
            try:
                commands.append(sp.parse_command(line))
            except sp.ProtocolError as exc:
                commands.append(sp.format_error(str(exc)))
        with self._lock:
            for (robot, _), command in zip(round_, commands):
                if isinstance(command, sp.Command):
                    robot.served[command.letter] += 1
        replies, reads, turns, bearings = list(commands), [], [], []
        for k, ((robot, _), command) in enumerate(zip(round_, commands)):
            if not isinstance(command, sp.Command):
                continue
            self._advance(robot)
            if command.letter == 'O':
                reads.append(k)
            elif command.letter == 'C':
                turns.append(self._position_move(robot, command.args))
                replies[k] = sp.format_reply('C')
            elif command == READ_BEARING:
                bearings.append(k)
            else:
                replies[k] = self._execute(robot, command)
        turns = [(index, deg) for index, deg in turns if deg]
        if turns:
            self.world.turn([deg for _, deg in turns], [index for index, _ in turns])
        if reads:
            rows = [round_[k][0].index for k in reads]
            for k, values in zip(reads, self.world.read(rows).tolist()):
                replies[k] = sp.format_reply('O', *values)
        if bearings:
            truth = self.world.bearing_deg
            for k in bearings:
                replies[k] = sp.format_z_reply(sp.Z_READ_BEARING, truth[round_[k][0].index])
        return replies

    def _execute(self, robot: _Robot, command: sp.Command) -> bytes:
        """The reply to a command other than O and C."""
        letter, args = command.letter, command.args
        if letter == 'B':
            return sp.format_reply('B', *VERSION)
        if letter == 'H':
            return sp.format_reply('H', *np.rint(robot.counters))
        if letter == 'G':
            robot.counters[:] = args
        elif letter == 'D':
            robot.speeds[:] = args
        elif letter == 'Z':
            return self._experimenter(robot.index, args)
        return sp.format_reply(letter)

    def _position_move(self, robot: _Robot, target: tuple) -> tuple[int, float]:
        """Stop the wheels and set the counters to ``target``; (robot, degrees to turn)."""
        robot.speeds[:] = 0.0
        travel = np.asarray(target, np.float64) - robot.counters
        robot.counters += travel
        return robot.index, self.wheels.rotation_deg(*travel)

    def _experimenter(self, index: int, args: tuple) -> bytes:
        sub, values = args[0], args[1:]
        try:
            if sub == sp.Z_LIGHT:
                self.world.set_condition(Condition(*values), index)
            elif sub == sp.Z_BEARING:
                self.world.set_bearing(values[0], index)
        except ValueError as exc:
            return sp.format_error(str(exc))
        if sub == sp.Z_READ_BEARING:
            return sp.format_z_reply(sub, float(self.world.bearing_deg[index]))
        return sp.format_z_reply(sub)

    def _advance(self, robot: _Robot) -> None:
        """Let the wheels run at their speeds for the wall-clock time since the last look."""
        now = time.monotonic()
        if robot.speeds.any():
            self._move(robot, robot.speeds * (now - robot.since) * 100.0)
        robot.since = now

    def _move(self, robot: _Robot, travel: np.ndarray) -> None:
        robot.counters += travel
        turn = self.wheels.rotation_deg(*travel)
        if turn:
            self.world.turn(turn, robot.index)

    # --- devices ------------------------------------------------------------------------

    def _close_robot(self, robot: _Robot) -> None:
        for fd in (robot.master, robot.slave):
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
        robot.master = robot.slave = -1

    def _close_all(self) -> None:
        for robot in self.robots:
            self._close_robot(robot)
        for fd in (self._wake_r, self._wake_w):
            try:
                os.close(fd)
            except OSError:
                pass
        self._wake_r = self._wake_w = -1


class EmulatorProcess:
    """An ``Emulator`` serving from a child process; use as a context manager.

    The robots then answer on the machine's other core instead of taking turns
    with the bridge, controller and manager for one interpreter lock.  The child
    is forked before the caller starts ROS (it must be: forking copies no DDS
    threads then), stops when the context exits or the parent dies, and ignores
    Ctrl-C, which the parent handles.  ``ports`` is there while it runs, and
    ``served`` once it has stopped.
    """

    def __init__(self, world: EmulatedWorld, **kwargs):
        self._args = (world, kwargs)
        self._conn = self._process = None
        self.ports: list[str] = []
        self._served: list[Counter] = []

    def served(self, robot: int) -> Counter:
        """Commands ``robot`` answered, by letter (known once the process has stopped)."""
        return Counter(self._served[robot]) if self._served else Counter()

    def __enter__(self) -> 'EmulatorProcess':
        import multiprocessing
        forking = multiprocessing.get_context('fork')
        self._conn, child = forking.Pipe()
        self._process = forking.Process(target=_serve_child,
                                        args=(os.getpid(), *self._args, child),
                                        name='khepera-emulator', daemon=True)
        self._process.start()
        child.close()
        if not self._conn.poll(30.0):
            self.__exit__()
            raise RuntimeError('the emulator process did not open its devices within 30 s')
        self.ports = self._conn.recv()
        return self

    def __exit__(self, *exc) -> None:
        try:
            self._conn.send('stop')
            if self._conn.poll(5.0):
                self._served = self._conn.recv()
        except (OSError, ValueError, EOFError):
            pass
        self._process.join(5.0)
        if self._process.is_alive():
            self._process.kill()
        self._conn.close()


def _serve_child(parent: int, world: EmulatedWorld, kwargs: dict, conn) -> None:
    import signal

    from ..lifeline import die_with_parent
    die_with_parent(parent)             # a SIGKILLed parent must not leave us holding the ptys
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)   # the parent stops us; or its death
    with Emulator(world, **kwargs) as emulator:
        conn.send(emulator.ports)
        try:
            conn.recv()                     # 'stop', or EOF when the parent is gone
            conn.send([emulator.served(r) for r in range(len(emulator.robots))])
        except (EOFError, OSError):
            pass
