"""The Khepera's ASCII serial protocol: the commands this project sends and their replies.

A command is an upper-case letter and comma-separated integer arguments, ended
by a carriage return; the robot answers with the same letter in lower case and
its values, ended by CR LF (Khepera user manual, "serial communication
protocol").  The subset used here:

  B            -> b,<bios>,<protocol>    software versions
  D,<l>,<r>    -> d                      wheel speeds, pulses per 10 ms (-127..127)
  G,<l>,<r>    -> g                      set the position counters, pulses
  C,<l>,<r>    -> c                      move the wheels to these counter values
  H            -> h,<l>,<r>              read the position counters
  O            -> o,<v0>,...,<v7>        ambient light, 0 bright .. 1023 dark

A pulse is 0.08 mm of wheel travel.  The emulator alone also answers ``Z``, its
experimenter's extension (see ``Z_*``), which a real robot does not know.

``parse_*`` functions check every field and raise ``ProtocolError`` with the
offending line, so a garbled or short reply can never pass as data.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

SENSORS = 8
SPEED_MAX = 127                     # pulses per 10 ms
POSITION_MAX = 2 ** 23 - 2          # largest target of the C command, pulses
COUNTER_MAX = 2 ** 31 - 1           # position counters are signed 32-bit
READING_MAX = 1023                  # 10-bit sensor values
MM_PER_PULSE = 0.08
LINE_END = b'\r\n'                  # what the robot sends after a reply
COMMAND_END = b'\r'                 # what the host sends after a command

# Emulator-only extension: what the experimenter does by hand with a real robot.
Z_BEARING = 'B'         # Z,B,<deg>            -> z,b        place the lamp at this bearing
Z_LIGHT = 'L'           # Z,L,<mm>,<ambient>   -> z,l        lamp distance and room darkness
Z_READ_BEARING = 'R'    # Z,R                  -> z,r,<deg>  ground-truth lamp bearing

_INT = re.compile(r'[-+]?\d+\Z')
_FLOAT = re.compile(r'[-+]?(\d+(\.\d*)?|\.\d+)([eE][-+]?\d+)?\Z')
_VERSION = re.compile(r'[0-9A-Za-z._-]+\Z')


@dataclass(frozen=True)
class Wheels:
    """The protocol speaks in wheel pulses; turning in place, each wheel travels the arc of
    half the wheel base, so one pulse turns the robot ``deg_per_pulse`` degrees."""

    wheel_base_mm: float = 53.0
    mm_per_pulse: float = MM_PER_PULSE

    def __post_init__(self):
        if not 10.0 <= self.wheel_base_mm <= 1000.0:
            raise ValueError(f'wheel_base_mm must be in [10, 1000], got {self.wheel_base_mm!r}')
        if not 0.001 <= self.mm_per_pulse <= 10.0:
            raise ValueError(f'mm_per_pulse must be in [0.001, 10], got {self.mm_per_pulse!r}')

    @property
    def deg_per_pulse(self) -> float:
        return math.degrees(2.0 * self.mm_per_pulse / self.wheel_base_mm)

    def rotation_deg(self, left, right) -> float:
        """Clockwise rotation of the robot when the wheels travel ``left``/``right`` pulses."""
        return (left - right) / 2.0 * self.deg_per_pulse


class ProtocolError(ValueError):
    """A line that breaks the protocol; the message quotes it and says what is wrong."""


@dataclass(frozen=True)
class Command:
    """A parsed command: its letter and its arguments (ints, or floats and a
    sub-command letter for the ``Z`` extension)."""

    letter: str
    args: tuple = ()


# Integer arguments of each standard command, as (low, high) per argument.
ARGUMENTS = {
    'B': (), 'H': (), 'O': (),
    'D': ((-SPEED_MAX, SPEED_MAX),) * 2,
    'G': ((-COUNTER_MAX - 1, COUNTER_MAX),) * 2,
    'C': ((-POSITION_MAX, POSITION_MAX),) * 2,
}
# Number of integer fields in each standard reply (B's are version strings).
REPLY_FIELDS = {'D': 0, 'G': 0, 'C': 0, 'H': 2, 'O': SENSORS}
Z_ARGUMENTS = {Z_BEARING: 1, Z_LIGHT: 2, Z_READ_BEARING: 0}

# Lines in the form this module writes them, recognised in one match; the field-by-field
# checks (and their messages) are for everything else.
_FAST_COMMAND = re.compile(rb'([%s])((?:,[-+]?[0-9]+)*)\Z' % ''.join(ARGUMENTS).encode())
_FAST_REPLY = {letter: re.compile(rb'%s(?:,[-+]?[0-9]+){%d}\r\n\Z' % (letter.lower().encode(), n))
               for letter, n in REPLY_FIELDS.items()}
_FAST_BEARING = re.compile(rb'z,r,([-+]?[0-9]+\.[0-9]+)\r\n\Z')


def _decode(line) -> str:
    if isinstance(line, (bytes, bytearray)):
        try:
            line = bytes(line).decode('ascii')
        except UnicodeDecodeError:
            raise ProtocolError(f'non-ASCII bytes in {bytes(line)!r}')
    return line.strip('\r\n')


def _int(text: str, what: str, line: str, low: int, high: int) -> int:
    if not _INT.match(text):
        raise ProtocolError(f'{what} must be an integer, got {text!r} in {line!r}')
    value = int(text)
    if not low <= value <= high:
        raise ProtocolError(f'{what} must be in [{low}, {high}], got {value} in {line!r}')
    return value


def _float(text: str, what: str, line: str) -> float:
    if not _FLOAT.match(text) or not math.isfinite(float(text)):
        raise ProtocolError(f'{what} must be a finite number, got {text!r} in {line!r}')
    return float(text)


# --- commands: the host formats, the robot (emulator) parses --------------------------

def format_command(letter: str, *args) -> bytes:
    """``format_command('D', 5, -5)`` -> ``b'D,5,-5\\r'``; arguments are checked."""
    if letter == 'Z':
        text = ','.join(['Z'] + [args[0]] + [_number(a) for a in args[1:]])
        parse_command(text)                   # the same checks the robot applies
    else:
        if letter not in ARGUMENTS:
            raise ValueError(f'unknown Khepera command {letter!r}; known: '
                             f'{sorted(ARGUMENTS) + ["Z"]}')
        values = [int(a) for a in args]
        text = ','.join([letter] + [str(v) for v in values])
        ranges = ARGUMENTS[letter]
        if len(values) != len(ranges) or not all(low <= v <= high for v, (low, high)
                                                 in zip(values, ranges)):
            parse_command(text)               # raises, naming what is wrong
    return text.encode('ascii') + COMMAND_END


def _number(value) -> str:
    return f'{float(value):.3f}'


def parse_command(line) -> Command:
    """The robot's side: a command line to a Command, or ProtocolError."""
    if isinstance(line, bytes):
        fast = _FAST_COMMAND.match(line)
        if fast:
            letter = fast[1].decode()
            values, ranges = tuple(map(int, fast[2].split(b',')[1:])), ARGUMENTS[letter]
            if len(values) == len(ranges) and all(low <= v <= high for v, (low, high)
                                                  in zip(values, ranges)):
                return Command(letter, values)
    text = _decode(line)
    parts = text.split(',')
    letter = parts[0]
    if letter == 'Z':
        return _parse_z(parts, text)
    if letter not in ARGUMENTS:
        raise ProtocolError(f'unknown command {letter!r} in {text!r}')
    ranges = ARGUMENTS[letter]
    if len(parts) - 1 != len(ranges):
        raise ProtocolError(f'{letter} takes {len(ranges)} arguments, got {len(parts) - 1} '
                            f'in {text!r}')
    return Command(letter, tuple(_int(p, f'{letter} argument {i + 1}', text, *r)
                                 for i, (p, r) in enumerate(zip(parts[1:], ranges))))


def _parse_z(parts: list[str], text: str) -> Command:
    if len(parts) < 2 or parts[1] not in Z_ARGUMENTS:
        raise ProtocolError(f'Z needs a sub-command, one of {sorted(Z_ARGUMENTS)}, in {text!r}')
    sub, count = parts[1], Z_ARGUMENTS[parts[1]]
    if len(parts) - 2 != count:
        raise ProtocolError(f'Z,{sub} takes {count} arguments, got {len(parts) - 2} in {text!r}')
    return Command('Z', (sub,) + tuple(_float(p, f'Z,{sub} argument', text)
                                       for p in parts[2:]))


# --- replies: the robot formats, the host parses ----------------------------------------

def format_reply(letter: str, *values) -> bytes:
    """``format_reply('O', *readings)`` -> ``b'o,500,...\\r\\n'``."""
    fields = [letter.lower()] + [v if isinstance(v, str) else str(int(v)) for v in values]
    return ','.join(fields).encode('ascii') + LINE_END


def format_error(reason: str) -> bytes:
    """The emulator's answer to a line it cannot execute: '?' and the reason."""
    return ('?,' + reason.replace(',', ';').replace('\r', ' ').replace('\n', ' ')).encode(
        'ascii', 'replace') + LINE_END


def format_z_reply(sub: str, *values: float) -> bytes:
    return ','.join(['z', sub.lower()] + [_number(v) for v in values]).encode('ascii') + LINE_END


def parse_reply(line, letter: str) -> tuple[int, ...]:
    """Integer fields of the reply to command ``letter``; ProtocolError if it is not one."""
    count = REPLY_FIELDS[letter]
    if isinstance(line, bytes) and _FAST_REPLY[letter].match(line):
        values = tuple(map(int, line[2:-2].split(b','))) if count else ()
        low, high = (0, READING_MAX) if letter == 'O' else (-COUNTER_MAX - 1, COUNTER_MAX)
        if not values or (low <= min(values) and max(values) <= high):
            return values
    text = _decode(line)
    parts = text.split(',')
    if parts[0] != letter.lower():
        raise ProtocolError(f'expected a reply to {letter} starting {letter.lower()!r}, '
                            f'got {text!r}')
    if len(parts) - 1 != count:
        raise ProtocolError(f'a reply to {letter} has {count} values, got {len(parts) - 1} '
                            f'in {text!r}')
    low, high = (0, READING_MAX) if letter == 'O' else (-COUNTER_MAX - 1, COUNTER_MAX)
    return tuple(_int(p, f'{letter.lower()} value {i}', text, low, high)
                 for i, p in enumerate(parts[1:]))


def parse_version(line) -> tuple[str, str]:
    """(bios, protocol) version strings of a reply to B."""
    text = _decode(line)
    parts = text.split(',')
    if len(parts) != 3 or parts[0] != 'b' or not all(_VERSION.match(p) for p in parts[1:]):
        raise ProtocolError(f'a reply to B looks like "b,<bios>,<protocol>", got {text!r}')
    return parts[1], parts[2]


def parse_z_reply(line, sub: str) -> tuple[float, ...]:
    """Values of the emulator's reply to ``Z,<sub>``."""
    if sub == Z_READ_BEARING and isinstance(line, bytes):
        fast = _FAST_BEARING.match(line)
        if fast and math.isfinite(float(fast[1])):
            return (float(fast[1]),)
    text = _decode(line)
    parts = text.split(',')
    count = 1 if sub == Z_READ_BEARING else 0
    if parts[:2] != ['z', sub.lower()] or len(parts) - 2 != count:
        raise ProtocolError(f'expected the emulator\'s reply "z,{sub.lower()}" with {count} '
                            f'values, got {text!r}')
    return tuple(_float(p, f'z,{sub.lower()} value', text) for p in parts[2:])
