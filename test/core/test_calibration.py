"""The calibration targets, on small runs: what the paper reports, and nothing else."""
import math

import numpy as np
import pytest

from khepera_noise_ros.core import baseline, network, task
from khepera_noise_ros.core.evolution import EAConfig, SteadyStateEA, evolve
from khepera_noise_ros.core.khepera import World
from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.experiment import config as settings
from khepera_noise_ros.experiment.protocol import play
from khepera_noise_ros.reality.effects import EffectsConfig
from khepera_noise_ros.reality.khepera_robot import InProcessRobots, KheperaRobots
from khepera_noise_ros.reality.world import CONDITIONS, EmulatedWorld, stationary

SEEDS = list(range(5000, 5300))


def pair(condition, seed=1, samples=600):
    x = stationary(EmulatedWorld(seed=seed), condition, samples)
    return np.corrcoef(x[:, 2], x[:, 3])[0, 1], np.ptp(x[:, 2])


def test_section_2_correlations_hold_in_the_tasks_light_regime():
    # the bright condition is the task's own lamp, the dark one the task's room
    assert CONDITIONS['bulb_1ft'] == CONDITIONS['task']
    assert CONDITIONS['room_dark'].ambient == World().ambient
    r = {name: pair(name) for name in ('bulb_1ft', 'bulb_2ft', 'room_fluorescent', 'room_dark')}
    assert abs(r['bulb_1ft'][0]) < 0.25                 # paper 5%
    assert 0.75 < r['bulb_2ft'][0] < 0.93               # paper 85%
    assert 0.65 < r['room_fluorescent'][0] < 0.87       # paper 76%
    assert r['room_dark'][0] > 0.93                     # paper 98%
    # darker = more correlated and a wider range
    assert r['bulb_2ft'][0] > r['bulb_1ft'][0] and r['room_dark'][0] > r['room_fluorescent'][0]
    assert r['bulb_2ft'][1] > r['bulb_1ft'][1] and r['room_dark'][1] > r['room_fluorescent'][1]


def test_the_task_lamp_puts_the_front_pair_where_figure_8_fitness_is_possible():
    # a fitness near 0.8 needs an intensity factor near 0.9: the facing pair reads bright
    table = World().light_table()
    assert table[2, 0] == table[3, 0] == World().floor


def _paired_loss(policy, world=World(), episode=task.Task()):
    clean = task.run(policy, SEEDS, len(SEEDS), world, NoiseModel('none'), episode)
    noisy = task.run(policy, SEEDS, len(SEEDS), world, NoiseModel.independent_only(0.10),
                     episode)
    d = (clean - noisy).astype(np.float64)
    return d.mean(), 1.97 * d.std(ddof=1) / math.sqrt(d.size)


def test_ten_percent_noise_costs_a_fixed_controller_measurably():
    loss, half = _paired_loss(baseline.turn_toward_light)
    assert loss - half > 0.005          # the whole 95% CI above half a percent of fitness


def test_a_controller_evolved_without_noise_loses_measurably_under_ten_percent():
    def evaluate(genomes, seeds):
        w = network.unpack(genomes)
        return task.run(lambda r: network.act(w, r), [int(s) for s in seeds], len(seeds),
                        World(), NoiseModel('none'), task.Task())
    ea = SteadyStateEA(EAConfig(best='retest'), seed=0)      # the paper's phase 1, no noise
    evolve([ea], evaluate)
    w = network.unpack(ea.best_genome[None].repeat(len(SEEDS), axis=0))
    loss, half = _paired_loss(lambda r: network.act(w, r))
    assert loss - half > 0              # the whole 95% CI of the loss above zero


@pytest.fixture(scope='module')
def phase1_bests():
    """Twelve phase-1 bests evolved under the paper's 5% independent noise, and their
    simulation test (step 2) on 20 episodes each."""
    noise = NoiseModel.independent_only(0.05)

    def evaluate(genomes, seeds):
        w = network.unpack(genomes)
        return task.run(lambda r: network.act(w, r), [int(s) for s in seeds], len(seeds),
                        World(), noise, task.Task())
    eas = [SteadyStateEA(EAConfig(best='retest'), seed=1000 + t) for t in range(12)]
    evolve(eas, evaluate)
    bests = np.array([ea.best_genome for ea in eas])
    return bests, _test(bests, evaluate)


def _test(genomes, evaluate, episodes=20):
    """Each controller's mean over the same ``episodes`` test episodes."""
    g = np.repeat(genomes, episodes, axis=0)
    seeds = np.tile(np.arange(episodes) + 7_000_000, len(genomes))
    return np.asarray(evaluate(g, seeds), float).reshape(len(genomes), episodes).mean(axis=1)


def _steps_3_and_5(bests, effects):
    """The first real test of the bests, and the real test after the paper's phase 2 (5
    generations of 10, seeded from each best) on the robot ``effects``."""
    world = EmulatedWorld(effects, seed=1, robots=240, start_bearing_deg=0.0)
    robots = KheperaRobots(InProcessRobots(world), World(), task.Task())

    def evaluate(genomes, seeds):
        return np.concatenate([play(robots, genomes[i:i + 240], seeds[i:i + 240])[0]
                               for i in range(0, len(seeds), 240)])
    eas = [SteadyStateEA(EAConfig(population=10, generations=5, best='retest'),
                         seed=2000 + t, seed_genome=g) for t, g in enumerate(bests)]
    evolve(eas, evaluate)
    return _test(bests, evaluate), _test(np.array([ea.best_genome for ea in eas]), evaluate)


def test_the_default_robot_opens_a_drop_that_training_on_it_recovers(phase1_bests):
    """Section 4.4: the first real test drops "dramatically" (at least 0.05 here), and real
    training recovers most of it (at least half).  Without the robot's effects, no drop."""
    bests, step2 = phase1_bests
    step3, step5 = _steps_3_and_5(bests, EffectsConfig.real_robot())
    drop = step2.mean() - step3.mean()
    assert drop >= 0.05, drop
    assert step5.mean() - step3.mean() >= 0.5 * drop, (drop, step5.mean() - step3.mean())
    plain, _ = _steps_3_and_5(bests[:4], EffectsConfig.none(0.01))
    assert abs(step2[:4].mean() - plain.mean()) < 0.02


def test_the_previous_default_robot_opened_a_drop_its_training_could_not_recover(
        phase1_bests):
    """Why it was replaced (benchmark/learnable_gap.py): its whole step of latency and 10%
    gain spread cost the controllers more than any the EA finds can win back."""
    bests, step2 = phase1_bests
    step3, step5 = _steps_3_and_5(bests, EffectsConfig.real_robot_v1())
    drop = step2.mean() - step3.mean()
    assert drop >= 0.05 and step5.mean() - step3.mean() < 0.25 * drop, (drop, step5.mean())


def test_every_emulated_robot_is_the_same_unit_by_default():
    def gains(world):
        return next(p.gains for p in world._chain.chain if hasattr(p, 'gains'))
    same = gains(EmulatedWorld(robots=3))
    assert np.array_equal(same[0], same[1]) and np.array_equal(same[1], same[2])
    own = EffectsConfig.real_robot().replace(sensor_gain_offset={'per_robot': True})
    gains = gains(EmulatedWorld(own, robots=2))
    assert not np.array_equal(gains[0], gains[1])


def test_the_measured_protocol_is_the_default_and_the_paper_s_a_preset():
    measured, paper = settings.load(), settings.load(protocol='paper')
    assert measured.data['protocol'] == 'measured' and measured.test_episodes >= 10
    assert measured.phase1.best == measured.phase2.best == 'retest'
    assert measured.reality['start_bearing_deg'] == 0.0
    assert paper.test_episodes == 1 and paper.phase2.best == 'ever'
    assert paper.reality['start_bearing_deg'] is None and paper.hash != measured.hash
    with pytest.raises(ValueError, match="'nope'"):
        settings.load(protocol='nope')


def test_a_placed_robot_starts_each_episode_facing_the_lamp():
    world = EmulatedWorld(robots=2, start_bearing_deg=0.0)
    world.turn([40.0, -70.0])
    world.set_condition('task')
    assert np.allclose(world.bearing_deg, 0.0)
    left = EmulatedWorld(robots=1)
    left.turn(40.0)
    left.set_condition('task')
    assert not np.allclose(left.bearing_deg, 0.0)
