"""The bridge backend over the emulator's pseudo-terminals (no ROS)."""
import logging
import os
import select
import threading
import tty

import numpy as np
import pytest

from khepera_noise_ros.core import baseline
from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.core.task import Episodes, Task
from khepera_noise_ros.reality import emulator as emulator_module
from khepera_noise_ros.reality import serial_robots
from khepera_noise_ros.reality import serial_protocol as sp
from khepera_noise_ros.reality.effects import EffectsConfig
from khepera_noise_ros.reality.emulator import Emulator
from khepera_noise_ros.reality.khepera_robot import InProcessRobots, KheperaRobots, \
    RobotUnreachable, SerialRobots
from khepera_noise_ros.reality.serial_link import Replies, exchange, request
from khepera_noise_ros.reality.world import EmulatedWorld

QUIET = EffectsConfig.none(sensor_noise=0.0)
TASK = Task(steps=12)


def run(backend, seeds, bearing=None, policy=baseline.turn_toward_light, before_step=None):
    """(readings (T, B, 8), bearings (T, B)) of one closed-loop episode;
    ``before_step(t)`` is called before step t."""
    readings = backend.reset(seeds, bearing_deg=bearing)
    out, bearings = [], []
    while readings is not None:
        out.append(readings)
        bearings.append(backend.bearing_deg.copy())
        if before_step is not None:
            before_step(backend.step_index + 1)
        readings = backend.step(*policy(readings))
    return np.array(out), np.array(bearings)


def in_process(seeds, start, world_seed=9):
    return run(KheperaRobots(InProcessRobots(EmulatedWorld(seed=world_seed, robots=len(seeds))),
                             task=TASK), seeds, start)


@pytest.fixture
def caplog_warnings(caplog):
    caplog.set_level(logging.INFO, logger='khepera_noise_ros.reality.serial_robots')
    return caplog


def serial_backend(em, **options):
    options.setdefault('timeout_s', 0.1)
    return KheperaRobots.on_ports(em.ports, task=TASK, **options)


def test_serial_link_equals_the_world_driven_in_process():
    """Every reading and bearing is the same whether the episode goes over the ptys or not."""
    seeds, start = [21, 22], [15.0, -40.0]
    with Emulator(EmulatedWorld(seed=9, robots=2)) as em:
        backend = serial_backend(em)
        over_serial = run(backend, seeds, start)
        backend.close()
        served = em.served(0)
    direct = in_process(seeds, start)
    assert np.array_equal(over_serial[0], direct[0])
    assert np.allclose(over_serial[1], direct[1], atol=1e-3)
    assert served['O'] == TASK.steps and served['C'] >= TASK.steps
    assert served['H'] == 0                     # an emulator's moves are over when it replies


def test_a_lost_reply_to_a_move_that_the_next_move_supersedes_is_not_resent(caplog_warnings):
    """On a perturbation step the turn and the knock go in one write; when the turn's reply
    is lost the knock's target stands, so nothing is resent and no reading changes."""
    seeds, start = [21, 22], [15.0, -40.0]

    def garble_the_turn(step):
        if step % TASK.perturb_every == 0:
            em.inject(1, 'garbled')

    with Emulator(EmulatedWorld(seed=9, robots=2)) as em:
        backend = serial_backend(em)
        over_serial = run(backend, seeds, start, before_step=garble_the_turn)
        backend.close()
    assert np.array_equal(over_serial[0], in_process(seeds, start)[0])
    messages = [r.getMessage() for r in caplog_warnings.records if r.levelname == 'WARNING']
    assert len(messages) == 2 and all('robot 1' in m and 'supersedes' in m for m in messages)


def test_counters_are_zeroed_before_they_run_out_of_range(monkeypatch):
    monkeypatch.setattr(serial_robots, 'REZERO_PULSES', 300)
    seeds, start = [21, 22], [15.0, -40.0]
    with Emulator(EmulatedWorld(seed=9, robots=2)) as em:
        backend = serial_backend(em)
        over_serial = run(backend, seeds, start)
        backend.close()
        zeroed = em.served(0)['G']
    assert zeroed > 1                           # at the start, and on the way
    assert np.array_equal(over_serial[0], in_process(seeds, start)[0])


@pytest.fixture
def fake_robots():
    """Three pseudo-terminals with nobody behind them: the test plays the robots."""
    pairs = [os.openpty() for _ in range(3)]
    for _, slave in pairs:
        tty.setraw(slave)
    yield [master for master, _ in pairs], [os.ttyname(slave) for _, slave in pairs]
    for fd in sum(pairs, ()):
        os.close(fd)


def read_line(fd) -> bytes:
    line = b''
    while not line.endswith(b'\r'):
        assert select.select([fd], [], [], 2.0)[0], f'nothing more after {line!r}'
        line += os.read(fd, 1)
    return line


def test_every_robot_is_sent_its_command_before_any_reply_is_awaited(fake_robots):
    masters, ports = fake_robots
    links = SerialRobots(ports, timeout_s=5.0).links
    result = {}
    host = threading.Thread(target=lambda: result.update(
        exchange({link: [request('O'), request('H')] for link in links})))
    host.start()
    try:
        heard = [read_line(m) + read_line(m) for m in masters]     # nobody has answered yet
        for i, master in reversed(list(enumerate(masters))):
            os.write(master, sp.format_reply('O', *range(i, i + 8)) + sp.format_reply('H', i, -i))
    finally:
        host.join(10.0)
    assert heard == [b'O\rH\r'] * 3
    assert [result[link] for link in links] == [[tuple(range(i, i + 8)), (i, -i)]
                                                for i in range(3)]
    for link in links:
        link.close()


def test_replies_are_matched_to_their_commands_in_order():
    replies = Replies([request('G', 0, 0), request('O'), request('H'), request('D', 0, 0)])
    assert not replies.feed(b'o,1,2,3,4,5,6,7,8\r\nh,1')        # 'g' lost, 'h' half there
    assert replies.feed(b',2\r\n~\r\nd\r\n')                      # a garbled extra line is not
    assert replies.outcomes[0].startswith('no complete reply')   # taken for the next reply
    assert replies.outcomes[1:3] == [((1, 2, 3, 4, 5, 6, 7, 8),), ((1, 2),)]
    assert replies.outcomes[3].startswith('garbled reply') and replies.pending == b'd\r\n'


def test_perturbations_are_the_simulators():
    """With no effects the robot's heading follows the simulator's step for step (to a
    wheel pulse): the knocks come from the same per-robot seed streams."""
    fixed = (np.array([1, -1]), np.array([3, 7]))
    sim = Episodes(noise=NoiseModel(model='none'), task=TASK)
    robots = KheperaRobots(InProcessRobots(EmulatedWorld(QUIET, robots=2)), task=TASK)
    _, sim_bearing = run(sim, [5, 6], [0.0, 30.0], lambda r: fixed)
    _, real_bearing = run(robots, [5, 6], [0.0, 30.0], lambda r: fixed)
    error = (real_bearing - sim_bearing + 180) % 360 - 180
    assert np.abs(error).max() < 0.1
    assert np.ptp(sim_bearing[:, 0]) > 10                              # knocks did happen


@pytest.mark.parametrize('fault', ['silent', 'garbled', 'short'])
def test_serial_faults_are_logged_and_retried(caplog_warnings, fault):
    with Emulator(EmulatedWorld(robots=1)) as em:
        backend = serial_backend(em, retries=2)
        backend.reset([1])
        em.inject(0, fault, count=2)
        assert backend.step([1], [4]).shape == (1, 8)
        backend.close()
    retries = [r.getMessage() for r in caplog_warnings.records if 'retrying' in r.getMessage()]
    assert len(retries) == 2 and 'robot 0' in retries[0]
    assert ('no complete reply' if fault == 'silent' else 'garbled reply') in retries[0]


def test_an_unreachable_robot_fails_the_episode_and_stops(caplog_warnings):
    with Emulator(EmulatedWorld(robots=1)) as em:
        backend = serial_backend(em, retries=1)
        backend.reset([1])
        em.inject(0, 'garbled', count=6)        # a step sends C, O and Z,R: each fails twice
        with pytest.raises(RobotUnreachable, match='robot 0 .* failed 2 times'):
            backend.step([1], [5])
        assert backend.failed and backend.done
        assert em.robots[0].speeds.tolist() == [0.0, 0.0]
        assert backend.reset([2]).shape == (1, 8)                     # a new episode works
        backend.close()


def test_a_device_that_disappears_fails_the_episode(caplog_warnings):
    with Emulator(EmulatedWorld(robots=2)) as em:
        backend = serial_backend(em, retries=1)
        backend.reset([1, 2])
        em.unplug(1)
        with pytest.raises(RobotUnreachable, match=r'robot 1 \(/dev/'):
            run(backend, [1, 2])
        backend.close()
    assert any('serial port failed' in r.getMessage() for r in caplog_warnings.records)


def test_close_stops_the_motors_that_ran():
    with Emulator(EmulatedWorld(robots=2)) as em:
        backend = serial_backend(em, turn_mode='speed', turn_speed=40)
        backend.reset([3, 4], bearing_deg=[0.0, 0.0])
        before = backend.bearing_deg.copy()
        backend.step([1, -1], [9, 9])                                 # a speed-mode turn
        after = backend.bearing_deg
        backend.bodies.links[0].ack('D', 10, -10)                     # left running
        assert em.robots[0].speeds.any()
        backend.close()
        assert not em.robots[0].speeds.any() and not em.robots[1].speeds.any()
    assert after[0] > before[0] and after[1] < before[1]             # right, then left


def test_a_real_robot_is_never_sent_emulator_commands(monkeypatch, caplog_warnings):
    monkeypatch.setattr(emulator_module, 'VERSION', ('5.02', '4.01'))
    with Emulator(EmulatedWorld(robots=1)) as em:
        backend = serial_backend(em)
        backend.reset([1], bearing_deg=[45.0])
        backend.step([1], [2])
        backend.close()
        assert backend.bearing_deg is None and em.served(0)['Z'] == 0
        assert em.served(0)['H'] > 0                # a real robot is watched until it arrives
    assert any('sets the heading by hand' in r.getMessage() for r in caplog_warnings.records)


def test_batch_larger_than_the_ports_is_refused():
    with Emulator(EmulatedWorld(robots=1)) as em:
        backend = serial_backend(em)
        with pytest.raises(ValueError, match='2 robots asked for, but there are 1'):
            backend.reset([1, 2])
        with pytest.raises(ValueError, match='ports must name at least one'):
            KheperaRobots.on_ports([])
        with pytest.raises(ValueError, match='turn_mode must be one of'):
            KheperaRobots.on_ports(em.ports, turn_mode='jump')
        backend.close()


def test_an_episode_survives_a_noisy_line(caplog_warnings):
    with Emulator(EmulatedWorld(robots=2), fault_rate=0.1, seed=2) as em:
        backend = serial_backend(em, timeout_s=0.05, retries=5)
        readings, _ = run(backend, [7, 8])
        backend.close()
    assert readings.shape == (TASK.steps, 2, 8) and not backend.failed
    assert any('retrying' in r.getMessage() for r in caplog_warnings.records)


def test_a_reply_that_comes_after_its_timeout_is_not_taken_for_the_next_one(fake_robots):
    """The robot answers the first O too late: the retry must get its own reply, not the
    late one (the link resynchronises with B, whose reply nothing else can be taken for)."""
    masters, ports = fake_robots
    (link,) = SerialRobots(ports[:1], timeout_s=0.3, retries=1).links
    result = {}
    host = threading.Thread(target=lambda: result.update(exchange({link: [request('O')]})))
    host.start()
    try:
        master = masters[0]
        assert read_line(master) == b'O\r'
        assert read_line(master) == b'B\r'          # sent once the first O timed out
        os.write(master, sp.format_reply('O', *range(8)))            # the late reply
        os.write(master, sp.format_reply('B', *emulator_module.VERSION))
        assert read_line(master) == b'O\r'
        os.write(master, sp.format_reply('O', *range(10, 18)))
    finally:
        host.join(10.0)
        link.close()
    assert result[link] == [tuple(range(10, 18))]
