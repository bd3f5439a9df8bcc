"""hardware_bridge in the node graph, against the emulator: the paper's steps 3-5."""
import time

import numpy as np
import pytest
from rclpy.parameter import Parameter

from khepera_noise_ros.core import evolution, network
from khepera_noise_ros.core.evaluation import CoreEvaluator
from khepera_noise_ros.core.task import Task
from khepera_noise_ros.nodes.controller import GENOMES, Controller
from khepera_noise_ros.nodes.evolution_manager import MANAGER_SPECS, EvolutionManager
from khepera_noise_ros.nodes.graph import EpisodeFailed, episode_fitness
from khepera_noise_ros.nodes.runtime import spinning
from khepera_noise_ros.nodes.hardware_bridge import HardwareBridge
from khepera_noise_ros.nodes.params import overrides
from khepera_noise_ros.reality.emulator import Emulator
from khepera_noise_ros.reality.khepera_robot import InProcessRobots, KheperaRobots
from khepera_noise_ros.reality.world import EmulatedWorld

STEPS = 20
WORLD_SEED = 11


def bridge(context, ports, **values):
    values = {'ports': list(ports), 'steps': STEPS, 'timeout_s': 2.0, 'retries': 1,
              'autostart': True, **values}
    return HardwareBridge(context=context, parameter_overrides=overrides(
        HardwareBridge.parameter_specs(), values))


def manager(context, **values):
    return EvolutionManager(context=context, parameter_overrides=overrides(
        MANAGER_SPECS, {'results_path': '', 'ready_timeout_s': 20.0, **values}))


def controller(context):
    return Controller(context=context, parameter_overrides=overrides([GENOMES], {}))


class Watched:
    """An evaluator that remembers the genomes it was asked to score."""

    def __init__(self, inner):
        self.inner, self.batches = inner, []

    def __call__(self, genomes, seeds):
        self.batches.append(np.array(genomes))
        return self.inner(genomes, seeds)

    def __getattr__(self, name):
        return getattr(self.inner, name)


def in_process_fitness(genomes, seeds, robots):
    """The same episode without ROS or serial: a fresh world with the emulator's seed."""
    backend = KheperaRobots(InProcessRobots(EmulatedWorld(seed=WORLD_SEED, robots=robots)),
                            task=Task(steps=STEPS))
    weights = network.unpack(genomes)
    readings, rows = backend.reset(seeds), []
    while readings is not None:
        direction, power = network.act(weights, readings)
        rows.append((readings.astype(np.float32), power))
        readings = backend.step(direction, power)
    return episode_fitness(np.stack([r for r, _ in rows]), np.stack([p for _, p in rows]))


def phase1_best() -> np.ndarray:
    """Step 1 at a tiny scale, in the core simulator."""
    ea = evolution.SteadyStateEA(evolution.EAConfig(population=6, generations=3), seed=2)
    evolution.evolve([ea], CoreEvaluator(task=Task(steps=STEPS)))
    return ea.best_genome


def test_bridge_parameters_are_checked(ros_context):
    node = bridge(ros_context, ['/dev/null'])
    try:
        for name, value, words in (('turn_mode', 'hop', 'turn_mode must be one of'),
                                   ('baudrate', 1234, 'baudrate must be a standard rate'),
                                   ('timeout_s', 100.0, ''), ('wheel_base_mm', 5.0, '')):
            result = node.set_parameters([Parameter(name, value=value)])[0]
            assert not result.successful and words in result.reason
        assert node.get_parameter('turn_mode').value == 'position'
        assert node.set_parameters([Parameter('retries', value=5)])[0].successful
        assert node.backend.bodies.links[0].settings.retries == 5           # rebuilt
    finally:
        node.destroy_node()


def test_steps_3_to_5_against_the_emulator(ros_context):
    """Test phase 1's best in reality, evolve from it in reality, test again: every episode
    runs emulator pty -> hardware_bridge -> controller -> manager and back."""
    best1 = phase1_best()
    with Emulator(EmulatedWorld(seed=WORLD_SEED, robots=4)) as em:
        nodes = [bridge(ros_context, em.ports), controller(ros_context),
                 manager(ros_context, phase=2, population=4, generations=2, seed=3,
                         seed_genome=best1.tolist(), stall_timeout_s=10.0)]
        with spinning(nodes, ros_context):
            mgr = nodes[2]
            mgr.evaluator = Watched(mgr.evaluator)
            mgr.evaluator.wait_ready(20.0)

            step3 = mgr.evaluator(best1[None], [101])                           # step 3
            assert step3 == pytest.approx(in_process_fitness(best1[None], [101], 4), abs=0)

            finished = mgr.start()                                              # step 4
            deadline = time.monotonic() + 45
            while not finished.done() and time.monotonic() < deadline:
                time.sleep(0.05)
            assert finished.done(), 'phase 2 did not finish'
            record = finished.result()

            best2 = np.array(record['best_genome'])                             # step 5
            step5 = mgr.evaluator(best2[None], [101])
        reads = sum(em.served(r)['O'] for r in range(4))

    phase2 = evolution.EAConfig(population=4, generations=2)
    seeded = mgr.evaluator.batches[1]                  # [0] was step 3
    assert np.array_equal(seeded, evolution.SteadyStateEA(phase2, 3, best1).ask()[0])
    assert not np.array_equal(seeded, evolution.SteadyStateEA(phase2, 3).ask()[0])
    assert np.abs(seeded - best1).max() <= 1.0         # seed + U(-1, 1)
    assert record['config']['seed_genome'] == best1.tolist()
    assert record['evaluations'] == 4 + 2 * 4 and record['episodes']['restarted'] == 0
    assert reads == STEPS * (1 + record['evaluations'] + 1)   # every step read over serial
    assert 0.0 <= step3[0] <= 1.0 and 0.0 <= step5[0] <= 1.0
    assert record['best_fitness'] >= max(record['trials'][0]['history'][0]['best'], 0.0)


def test_unreachable_robot_fails_the_episode_unscored(ros_context):
    with Emulator(EmulatedWorld(seed=1, robots=1)) as em:
        nodes = [bridge(ros_context, em.ports), controller(ros_context),
                 manager(ros_context, stall_timeout_s=10.0, max_retries=1)]
        with spinning(nodes, ros_context):
            evaluator = nodes[2].evaluator
            evaluator.wait_ready(20.0)
            genome = np.zeros((1, network.GENES))
            assert evaluator(genome, [1]).shape == (1,)
            em.unplug(0)
            evaluator.stall_timeout_s = 0.5
            with pytest.raises(EpisodeFailed, match='failed 2 times'):
                evaluator(genome, [2])
        assert not em.robots[0].speeds.any()
