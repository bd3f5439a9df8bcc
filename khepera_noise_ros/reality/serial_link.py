"""Serial links to Kheperas: one port per robot, commands to all ports at once, retries."""
from __future__ import annotations

import functools
import math
import os
import select
import termios
import time
from dataclasses import dataclass
from typing import Any, Callable

import serial

from . import serial_protocol as sp

PORT_ERRORS = (serial.SerialException, OSError, termios.error)   # a device that went away
EMULATOR_PROTOCOL = 'emulator'      # the emulator's protocol version in its reply to B


class RobotUnreachable(RuntimeError):
    """A robot did not answer sensibly after every retry: the episode fails."""


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
