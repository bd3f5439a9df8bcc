"""``SerialRobots``: the bodies of an episode on Kheperas over serial ports."""
from __future__ import annotations

import logging
import time

import numpy as np

from . import serial_protocol as sp
from .serial_link import IDENTIFY, PARSE_C, READ_BEARING, READ_COUNTERS, READ_LIGHT, \
    STOP_MOTORS, ZERO_COUNTERS, LinkSettings, Request, SerialLink, exchange, request, \
    stop_motors, z_request
from .world import Condition

TURN_MODES = ('position', 'speed')
POSITION_SPEED = 2000.0             # pulses/s, the Khepera's default position-mode top speed
ON_TARGET = 1                       # pulses from the target that count as arrived
REZERO_PULSES = sp.POSITION_MAX // 2    # counters re-zeroed before a target gets this far


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
                         for link in self._active])

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
