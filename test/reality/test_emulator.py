"""The robot emulator on pseudo-terminals: in-process and as `khepera-noise emulate`."""
import os
import select
import signal
import subprocess
import sys
import time

import pytest
import serial

from khepera_noise_ros.reality import serial_protocol as sp
from khepera_noise_ros.reality.effects import EffectsConfig
from khepera_noise_ros.reality.emulator import Emulator, EmulatorProcess
from khepera_noise_ros.reality.world import EmulatedWorld

QUIET = EffectsConfig.none(sensor_noise=0.0)


@pytest.fixture
def emulator():
    with Emulator(EmulatedWorld(QUIET, robots=2)) as em:
        yield em


def talk(port: serial.Serial, line: bytes) -> bytes:
    port.write(line)
    reply = port.read_until(b'\n')
    assert reply.endswith(sp.LINE_END), reply
    return reply


def open_port(path):
    return serial.Serial(path, 9600, timeout=2.0)


def test_each_robot_answers_the_protocol_on_its_own_device(emulator):
    assert len(emulator.ports) == 2 and all(os.path.exists(p) for p in emulator.ports)
    with open_port(emulator.ports[0]) as a, open_port(emulator.ports[1]) as b:
        assert sp.parse_version(talk(a, b'B\r')) == ('5.02', 'emulator')
        talk(b, sp.format_command('Z', sp.Z_BEARING, 90.0))
        front_a = sp.parse_reply(talk(a, b'O\r'), 'O')
        front_b = sp.parse_reply(talk(b, b'O\n'), 'O')          # LF also ends a command
    assert front_a[2] < 100 and front_a[0] == 500               # lamp ahead of robot 0
    assert front_b[0] < 100 and front_b[2] > front_a[2]         # lamp on robot 1's left
    assert emulator.served(0)['O'] == 1 and emulator.served(1)['Z'] == 1


def test_position_moves_turn_the_world_at_once(emulator):
    deg_per_pulse = sp.Wheels().deg_per_pulse
    with open_port(emulator.ports[0]) as port:
        assert talk(port, b'G,0,0\r') == b'g\r\n'
        assert talk(port, b'C,100,-100\r') == b'c\r\n'
        assert sp.parse_reply(talk(port, b'H\r'), 'H') == (100, -100)
        bearing = sp.parse_z_reply(talk(port, b'Z,R\r'), 'R')[0]
        assert bearing == pytest.approx(100 * deg_per_pulse, abs=1e-3)   # right turn: CCW lamp
        talk(port, b'C,50,-50\r')                               # back by 50 pulses
        assert emulator.world.bearing_deg[0] == pytest.approx(50 * deg_per_pulse)


def test_wheel_speeds_turn_the_robot_in_wall_clock_time(emulator):
    with open_port(emulator.ports[1]) as port:
        talk(port, b'D,-10,10\r')                               # left turn
        time.sleep(0.05)
        talk(port, b'D,0,0\r')
        left, right = sp.parse_reply(talk(port, b'H\r'), 'H')
        time.sleep(0.05)
        assert sp.parse_reply(talk(port, b'H\r'), 'H') == (left, right)   # stopped
    assert left < 0 < right and left == -right
    assert emulator.world.bearing_deg[1] < 0


def test_bad_lines_get_a_reason_and_the_robot_carries_on(emulator):
    with open_port(emulator.ports[0]) as port:
        assert talk(port, b'D,900,0\r').startswith(b'?,D argument 1 must be in')
        assert talk(port, b'Z,L,-5,500\r').startswith(b'?,lamp_distance_mm must be')
        assert talk(port, b'B\r') == b'b,5.02,emulator\r\n'


@pytest.mark.parametrize('fault', ['silent', 'garbled', 'short'])
def test_injected_faults_break_exactly_the_next_reply(emulator, fault):
    emulator.inject(0, fault)
    with serial.Serial(emulator.ports[0], timeout=0.2) as port:
        port.write(b'H\r')
        first = port.read_until(b'\n')
        assert talk(port, b'H\r') == b'h,0,0\r\n'
    if fault == 'silent':
        assert first == b''
    else:
        with pytest.raises(sp.ProtocolError):
            sp.parse_reply(first, 'H')


def test_commands_waiting_together_are_answered_together(monkeypatch):
    """Robots written to before the emulator looks are one round: one reading of the world
    for all of them, the same values as one at a time; a robot alone still gets its reply."""
    world = EmulatedWorld(seed=3, robots=3)
    rounds = []
    read = world.read
    monkeypatch.setattr(world, 'read', lambda rows: rounds.append(list(rows)) or read(rows))
    emulator = Emulator(world)
    ports = [open_port(path) for path in emulator.ports]
    try:
        for port in ports:
            port.write(b'O\rZ,R\r')
        masters = [robot.master for robot in emulator.robots]
        deadline = time.monotonic() + 5
        while len(select.select(masters, [], [], 0.1)[0]) < 3 and time.monotonic() < deadline:
            pass                                # until the kernel has passed every line on
        emulator.start()
        together = [sp.parse_reply(port.read_until(b'\n'), 'O') for port in ports]
        assert [sp.parse_z_reply(port.read_until(b'\n'), 'R') for port in ports] == [(0.0,)] * 3
        alone = sp.parse_reply(talk(ports[1], b'O\r'), 'O')
    finally:
        for port in ports:
            port.close()
        emulator.stop()
    assert rounds == [[0, 1, 2], [1]]
    one_by_one = EmulatedWorld(seed=3, robots=3)
    assert together == [tuple(one_by_one.read(i)) for i in range(3)]
    assert alone == tuple(one_by_one.read(1))


def test_unplug_and_stop_remove_the_devices():
    emulator = Emulator(EmulatedWorld(robots=2)).start()
    ports = emulator.ports
    emulator.unplug(0)
    deadline = time.monotonic() + 5
    while os.path.exists(ports[0]) and time.monotonic() < deadline:
        time.sleep(0.01)
    assert not os.path.exists(ports[0]) and os.path.exists(ports[1])
    emulator.stop()
    emulator.stop()                                             # twice is fine
    assert not emulator._thread.is_alive() and not os.path.exists(ports[1])


def test_an_emulator_process_serves_like_the_thread_and_leaves_nothing_behind():
    """The same world answers the same from a child process; its devices go with it."""
    def readings(emulator):
        with open_port(emulator.ports[1]) as port:
            talk(port, sp.format_command('Z', sp.Z_BEARING, 30.0))
            return [sp.parse_reply(talk(port, b'O\r'), 'O') for _ in range(5)]
    with Emulator(EmulatedWorld(seed=4, robots=2)) as thread:
        expected = readings(thread)
    with EmulatorProcess(EmulatedWorld(seed=4, robots=2)) as child:
        ports, process = child.ports, child._process
        assert process.pid != os.getpid() and process.is_alive()
        assert readings(child) == expected
    assert not process.is_alive() and not any(os.path.exists(p) for p in ports)
    assert child.served(1) == {'Z': 1, 'O': 5} and child.served(0) == {}


def test_emulate_command_prints_its_devices_and_stops_on_sigterm():
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    proc = subprocess.Popen([sys.executable, '-m', 'khepera_noise_ros.cli', 'emulate',
                             '--robots', '2', '--seed', '4'], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=env)
    try:
        ports = [proc.stdout.readline().decode().strip() for _ in range(2)]
        assert all(p.startswith('/dev/') for p in ports), ports
        with open_port(ports[1]) as port:
            assert sp.parse_version(talk(port, b'B\r'))[1] == 'emulator'
            assert len(sp.parse_reply(talk(port, b'O\r'), 'O')) == 8
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
        assert b'stopped' in proc.stderr.read()
    finally:
        with proc:                  # closes the pipes
            if proc.poll() is None:
                proc.kill()


def test_emulate_measure_prints_section_2(capsys):
    from khepera_noise_ros import cli
    assert cli.main(['emulate', '--measure', '--samples', '200']) == 0
    out = capsys.readouterr().out
    rows = {line.split()[0]: line.split() for line in out.splitlines()[1:]}
    assert set(rows) == {'bulb_1ft', 'bulb_2ft', 'room_fluorescent', 'room_dark'}
    assert float(rows['room_dark'][5]) > float(rows['bulb_1ft'][5])


def test_emulate_refuses_bad_options(tmp_path, capsys):
    from khepera_noise_ros import cli
    bad = tmp_path / 'bad.yaml'
    bad.write_text('effects: {sensor_latency: {strength: -1}}\n')
    assert cli.main(['emulate', '--config', str(bad)]) == 2
    assert 'effects.sensor_latency.strength' in capsys.readouterr().err
    assert cli.main(['emulate', '--robots', '0']) == 2
