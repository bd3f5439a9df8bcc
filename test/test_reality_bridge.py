"""The bridge backend over the emulator's pseudo-terminals (no ROS)."""
import logging

import numpy as np
import pytest

from khepera_noise_ros.core import baseline
from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.core.task import Episodes, Task
from khepera_noise_ros.reality import emulator as emulator_module
from khepera_noise_ros.reality.effects import EffectsConfig
from khepera_noise_ros.reality.emulator import Emulator
from khepera_noise_ros.reality.khepera_robot import InProcessRobots, KheperaRobots, \
    RobotUnreachable
from khepera_noise_ros.reality.world import EmulatedWorld

QUIET = EffectsConfig.none(sensor_noise=0.0)
TASK = Task(steps=12)


def run(backend, seeds, bearing=None, policy=baseline.turn_toward_light):
    """(readings (T, 8, B), bearings (T, B)) of one closed-loop episode."""
    readings = backend.reset(seeds, bearing_deg=bearing)
    out, bearings = [], []
    while readings is not None:
        out.append(readings)
        bearings.append(backend.bearing_deg.copy())
        readings = backend.step(*policy(readings))
    return np.array(out), np.array(bearings)


@pytest.fixture
def caplog_warnings(caplog):
    caplog.set_level(logging.INFO, logger='khepera_noise_ros.reality.khepera_robot')
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
    in_process = run(KheperaRobots(InProcessRobots(EmulatedWorld(seed=9, robots=2)),
                                   task=TASK), seeds, start)
    assert np.array_equal(over_serial[0], in_process[0])
    assert np.allclose(over_serial[1], in_process[1], atol=1e-3)
    assert served['O'] == TASK.steps and served['C'] >= TASK.steps


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
        assert backend.step([1], [4]).shape == (8, 1)
        backend.close()
    retries = [r.getMessage() for r in caplog_warnings.records if 'retrying' in r.getMessage()]
    assert len(retries) == 2 and 'robot 0' in retries[0]
    assert ('no complete reply' if fault == 'silent' else 'garbled reply') in retries[0]


def test_an_unreachable_robot_fails_the_episode_and_stops(caplog_warnings):
    with Emulator(EmulatedWorld(robots=1)) as em:
        backend = serial_backend(em, retries=1)
        backend.reset([1])
        em.inject(0, 'garbled', count=2)
        with pytest.raises(RobotUnreachable, match='robot 0 .* failed 2 times'):
            backend.step([1], [5])
        assert backend.failed and backend.done
        assert em.robots[0].speeds.tolist() == [0.0, 0.0]
        assert backend.reset([2]).shape == (8, 1)                     # a new episode works
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
    assert readings.shape == (TASK.steps, 8, 2) and not backend.failed
    assert any('retrying' in r.getMessage() for r in caplog_warnings.records)
