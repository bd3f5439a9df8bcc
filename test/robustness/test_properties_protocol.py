"""Property tests (hypothesis) of the message unpackers and the serial protocol parser: any
input either parses to a value that keeps the contract or is refused with a one-line
reason of the project's own error type, never another exception."""
from __future__ import annotations

import math
import os

import numpy as np
from hypothesis import HealthCheck, given, settings, strategies as st
from std_msgs.msg import Float64MultiArray, Int32MultiArray, MultiArrayDimension

from khepera_noise_ros.nodes import protocol
from khepera_noise_ros.reality import serial_protocol as sp

EXAMPLES = int(os.environ.get('KHEPERA_NOISE_EXAMPLES', '150'))   # 300: the thorough run
SETTINGS = settings(max_examples=EXAMPLES, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])


def refused_in_one_line(exc: BaseException, kind=ValueError) -> None:
    assert isinstance(exc, kind), f'{type(exc).__name__}: {exc}'
    text = str(exc)
    assert text and '\n' not in text, repr(text)


def parses_or_refuses(parse, value, kind):
    """``parse(value)``, or None after checking a refusal is ``kind`` in one line."""
    try:
        return parse(value)
    except Exception as exc:        # noqa: BLE001 - the property is about its type
        refused_in_one_line(exc, kind)
        return None


# -- nodes/protocol.py -------------------------------------------------------------------

UNPACK = {'light': protocol.unpack_light, 'bearing': protocol.unpack_bearing,
          'fitness': protocol.unpack_fitness, 'genomes': protocol.unpack_genomes,
          'episode_start': protocol.unpack_episode_start}
RNG = np.random.default_rng(16)
VALID = {       # one well-formed serialized message of each kind, to damage
    'light': protocol.pack_light(3, 4, RNG.uniform(0, 500, (8, 5)), raw=True),
    'bearing': protocol.pack_bearing(3, 4, RNG.uniform(-180, 180, 5), raw=True),
    'fitness': protocol.pack_fitness(3, 60, RNG.uniform(0, 1, 5), raw=True),
    'genomes': protocol.pack_genomes(3, RNG.uniform(-1, 1, (5, 20)), raw=True),
    'episode_start': protocol.pack_episode_start(3, RNG.integers(0, 2 ** 53, 5), raw=True),
    'cmd_turn': protocol.pack_cmd_turn(3, 4, np.ones(5, int), np.arange(5), raw=True),
}
UNPACK_ALL = {**UNPACK, 'cmd_turn': protocol.unpack_cmd_turn}

floats = st.floats(allow_nan=True, allow_infinity=True, width=64)
dims = st.lists(st.builds(MultiArrayDimension, label=st.sampled_from(['robots', 'sensors',
                                                                      'genes', '', 'x']),
                          size=st.integers(0, 50), stride=st.integers(0, 500)), max_size=3)


def check(name: str, result) -> None:
    """What an accepted message must hold."""
    if name == 'light':
        assert np.all(np.isfinite(result.values)) and np.all(result.values >= 0)
        assert np.all(result.values <= protocol.DARK)
    elif name == 'fitness':
        assert np.all((result.values >= 0) & (result.values <= 1))
    elif name == 'cmd_turn':
        assert set(np.unique(result.values[:, 0])) <= {-1, 1}
        assert np.all((result.values[:, 1] >= 0) & (result.values[:, 1] <= 9))
    elif name == 'genomes':
        episode, genomes = result
        assert genomes.ndim == 2 and np.all(np.isfinite(genomes))
    elif name == 'episode_start':
        seeds = result[1]
        assert np.all((np.asarray(seeds) >= 0) & (np.asarray(seeds) < 2 ** 53))


@SETTINGS
@given(name=st.sampled_from(sorted(UNPACK)), layout=dims, offset=st.integers(0, 2 ** 32 - 1),
       data=st.lists(floats, max_size=120))
def test_any_float_message_unpacks_to_the_contract_or_is_malformed(name, layout, offset, data):
    msg = Float64MultiArray(data=data)
    msg.layout.dim = layout
    msg.layout.data_offset = offset
    result = parses_or_refuses(UNPACK[name], msg, protocol.Malformed)
    if result is not None:
        check(name, result)


@SETTINGS
@given(layout=dims, offset=st.integers(0, 2 ** 32 - 1),
       data=st.lists(st.integers(-2 ** 31, 2 ** 31 - 1), max_size=60))
def test_any_int_message_unpacks_to_the_contract_or_is_malformed(layout, offset, data):
    msg = Int32MultiArray(data=data)
    msg.layout.dim = layout
    msg.layout.data_offset = offset
    result = parses_or_refuses(protocol.unpack_cmd_turn, msg, protocol.Malformed)
    if result is not None:
        check('cmd_turn', result)


@SETTINGS
@given(name=st.sampled_from(sorted(UNPACK_ALL)), data=st.data())
def test_damaged_serialized_bytes_unpack_to_the_contract_or_are_malformed(name, data):
    raw = bytearray(VALID[name])
    for _ in range(data.draw(st.integers(1, 6))):
        how = data.draw(st.sampled_from(['flip', 'cut', 'insert', 'byte']))
        at = data.draw(st.integers(0, max(len(raw) - 1, 0)))
        if how == 'flip' and raw:
            raw[at] ^= 1 << data.draw(st.integers(0, 7))
        elif how == 'byte' and raw:
            raw[at] = data.draw(st.integers(0, 255))
        elif how == 'cut':
            del raw[at:]
        else:
            raw[at:at] = data.draw(st.binary(min_size=1, max_size=16))
    result = parses_or_refuses(UNPACK_ALL[name], bytes(raw), protocol.Malformed)
    if result is not None:
        check(name, result)


@SETTINGS
@given(name=st.sampled_from(sorted(UNPACK_ALL)), raw=st.binary(max_size=200))
def test_random_bytes_are_malformed_or_keep_the_contract(name, raw):
    result = parses_or_refuses(UNPACK_ALL[name], raw, protocol.Malformed)
    if result is not None:
        check(name, result)


# -- reality/serial_protocol.py ----------------------------------------------------------

tokens = st.one_of(st.integers(-10 ** 12, 10 ** 12).map(str), floats.map(repr),
                   st.text(max_size=6), st.sampled_from(['', ' ', '-', '+1', '0x10', '1e999']))
letters = st.sampled_from(list('ABCDEFGHKLNOZabcdhlnoz?') + ['', ',', '\x00'])
lines = st.one_of(
    st.binary(max_size=80),
    st.text(max_size=80),
    st.builds(lambda letter, parts, end: ','.join([letter, *parts]) + end, letters,
              st.lists(tokens, max_size=6), st.sampled_from(['', '\n', '\r\n', '\r'])))


@SETTINGS
@given(line=lines)
def test_any_command_line_parses_or_is_a_protocol_error(line):
    command = parses_or_refuses(sp.parse_command, line, sp.ProtocolError)
    if command is not None:
        assert command.letter.isupper()
        assert all(isinstance(a, str) or (isinstance(a, (int, float)) and math.isfinite(a))
                   for a in command.args)


@SETTINGS
@given(line=lines, letter=st.sampled_from(sorted(sp.REPLY_FIELDS)))
def test_any_reply_line_parses_or_is_a_protocol_error(line, letter):
    values = parses_or_refuses(lambda x: sp.parse_reply(x, letter), line, sp.ProtocolError)
    if values is not None:
        assert all(isinstance(v, int) for v in values)
    parses_or_refuses(sp.parse_version, line, sp.ProtocolError)
    for sub in sorted(sp.Z_ARGUMENTS):
        z = parses_or_refuses(lambda x: sp.parse_z_reply(x, sub), line, sp.ProtocolError)
        if z is not None:
            assert all(math.isfinite(v) for v in z)
