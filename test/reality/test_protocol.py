"""The Khepera serial protocol: formatting, strict parsing, wheel geometry."""
import math

import pytest

from khepera_noise_ros.reality import serial_protocol as sp


def test_commands_are_formatted_as_the_robot_expects():
    assert sp.format_command('O') == b'O\r'
    assert sp.format_command('D', 5, -5) == b'D,5,-5\r'
    assert sp.format_command('C', 1234, -1234) == b'C,1234,-1234\r'
    assert sp.format_command('Z', sp.Z_LIGHT, 5, 500) == b'Z,L,5.000,500.000\r'


@pytest.mark.parametrize('letter, args', [('D', (128, 0)), ('D', (0,)), ('Q', ()),
                                          ('C', (2 ** 23, 0)), ('O', (1,))])
def test_bad_commands_are_refused_before_they_are_sent(letter, args):
    with pytest.raises(ValueError):
        sp.format_command(letter, *args)


def test_the_robot_parses_what_the_host_sends():
    assert sp.parse_command(b'D,5,-5\r') == sp.Command('D', (5, -5))
    assert sp.parse_command('G,0,0\n') == sp.Command('G', (0, 0))
    assert sp.parse_command(b'Z,B,-12.5') == sp.Command('Z', ('B', -12.5))
    assert sp.parse_command(b'Z,R') == sp.Command('Z', ('R',))


@pytest.mark.parametrize('line, words', [
    (b'D,5', 'takes 2 arguments'), (b'D,5,x', 'must be an integer'),
    (b'D,500,0', 'must be in [-127, 127]'), (b'X', 'unknown command'),
    (b'Z,Q,1', 'sub-command'), (b'Z,B', 'takes 1 arguments'), (b'Z,B,nan', 'finite'),
    (b'O\xff', 'non-ASCII'), (b'', 'unknown command')])
def test_malformed_commands_name_the_problem(line, words):
    with pytest.raises(sp.ProtocolError, match=words.replace('[', r'\[')):
        sp.parse_command(line)


def test_replies_round_trip():
    readings = (500, 499, 120, 80, 480, 500, 510, 505)
    assert sp.parse_reply(sp.format_reply('O', *readings), 'O') == readings
    assert sp.parse_reply(sp.format_reply('H', 100, -100), 'H') == (100, -100)
    assert sp.parse_reply(sp.format_reply('D'), 'D') == ()
    assert sp.format_reply('D') == b'd\r\n'
    assert sp.parse_version(sp.format_reply('B', '5.02', 'emulator')) == ('5.02', 'emulator')
    assert sp.parse_z_reply(sp.format_z_reply('R', -12.25), 'R') == (-12.25,)
    assert sp.parse_z_reply(sp.format_z_reply('L'), 'L') == ()


@pytest.mark.parametrize('line, letter', [
    (b'o,0,1,1023,+7,0042,5,6,7\r\n', 'O'), (b'h,-2147483648,2147483647\r\n', 'H'),
    (b'c\r\n', 'C'), (b'o,1,2,3,4,5,6,7,1024\r\n', 'O'), (b'h,1,2147483648\r\n', 'H')])
def test_replies_in_the_usual_form_parse_as_any_other(line, letter):
    """Bytes in the form the emulator writes take a shortcut; text takes the general path;
    both accept and refuse the same lines."""
    try:
        expected = sp.parse_reply(line.decode(), letter)
    except sp.ProtocolError as exc:
        with pytest.raises(sp.ProtocolError) as refused:
            sp.parse_reply(line, letter)
        assert str(refused.value) == str(exc)
    else:
        assert sp.parse_reply(line, letter) == expected
    assert sp.parse_z_reply(b'z,r,-12.250\r\n', 'R') == sp.parse_z_reply('z,r,-12.250', 'R')
    assert sp.parse_command(b'C,+5,-0005') == sp.parse_command('C,+5,-0005') == \
        sp.Command('C', (5, -5))


@pytest.mark.parametrize('line, letter, words', [
    (b'o,1,2,3,4,5,6,7\r\n', 'O', 'has 8 values, got 7'),          # short
    (b'o,1,2,3,4,5,6,7,8,9\r\n', 'O', 'has 8 values, got 9'),
    (b'o,1,2,3,~,5,6,7,8\r\n', 'O', 'must be an integer'),         # garbled
    (b'o,1,2,3,4,5,6,7,2000\r\n', 'O', 'must be in'),
    (b'h,1\r\n', 'H', 'has 2 values'),
    (b'd,\r\n', 'D', 'has 0 values'),
    (b'\r\n', 'D', "starting 'd'"),
    (b'c\r\n', 'D', "starting 'd'"),                               # a reply to another command
    (b'?,unknown command\r\n', 'O', "starting 'o'")])
def test_bad_replies_never_pass_as_data(line, letter, words):
    with pytest.raises(sp.ProtocolError, match=words):
        sp.parse_reply(line, letter)


@pytest.mark.parametrize('line', [b'b,5.02\r\n', b'b,5.02,1,2\r\n', b'x,5.02,1\r\n',
                                  b'b,5 02,1\r\n'])
def test_bad_version_replies_are_refused(line):
    with pytest.raises(sp.ProtocolError):
        sp.parse_version(line)


def test_error_reply_is_one_line_that_parses_as_nothing():
    line = sp.format_error('bad, worse\r\nworst')
    assert line.count(b'\n') == 1 and line.endswith(sp.LINE_END)
    with pytest.raises(sp.ProtocolError):
        sp.parse_reply(line, 'D')


def test_wheel_geometry_of_a_turn_in_place():
    wheels = sp.Wheels()                      # 53 mm base, 0.08 mm per pulse
    pulses_per_turn = 53.0 * math.pi / 0.08   # each wheel travels the circle of the base
    assert wheels.deg_per_pulse == pytest.approx(360.0 / pulses_per_turn)
    assert wheels.rotation_deg(100, -100) == pytest.approx(100 * wheels.deg_per_pulse)
    assert wheels.rotation_deg(-50, 50) == pytest.approx(-50 * wheels.deg_per_pulse)
    assert wheels.rotation_deg(70, 70) == 0.0                        # driving straight
    with pytest.raises(ValueError, match='wheel_base_mm'):
        sp.Wheels(wheel_base_mm=1.0)
