"""The transfer experiment's measured protocol: arms, re-tested bests, shared test episodes,
intervals, verdicts, the share recovered, do no harm, and a robot that stops."""
import dataclasses

import numpy as np
import pytest

from khepera_noise_ros import effects as fx
from khepera_noise_ros.core import evolution
from khepera_noise_ros.core.evolution import EAConfig
from khepera_noise_ros.experiment import transfer, transfer_report, transfer_stats
from khepera_noise_ros.simconfig import SimConfig

SMALL = EAConfig(population=4, generations=2, best='retest', retest_episodes=2)
KEPT = {'real_fitness_before', 'real_fitness_after', 'sim_fitness_before', 'sim_fitness_after',
        'fitness_gap_before', 'fitness_gap_after', 'trials', 'gap_t', 'gap_p', 'real_t',
        'real_p', 'test', 'ea', 'test_episodes'}
ADDED = {'arms', 'real_fitness_robot_trained', 'share_recovered', 'share_recovered_interval',
         'verdict', 'verdict_text', 'recommended', 'recommendation', 'status'}


class Recorder:
    """Reality = the stock simulator, remembering every batch it was asked for."""

    def __init__(self, fail_at: int | None = None):
        self.simulator = transfer.SimEvaluator(SimConfig())
        self.calls, self.fail_at = [], fail_at

    def __call__(self, genomes, seeds):
        if self.fail_at is not None and len(self.calls) >= self.fail_at:
            raise RuntimeError("robot 1 (/dev/ttyUSB1) unreachable: 'N' failed 4 times")
        self.calls.append(np.array(seeds))
        return self.simulator(genomes, seeds)


def simulators():
    return transfer.arms(SimConfig(), SimConfig(effects=(fx.ActuatorTurnError(scale=0.5),)))


def test_every_arm_is_tested_on_the_same_episodes_and_the_block_keeps_its_keys():
    reality = Recorder()
    out = transfer.run(simulators(), reality, trials=3, ea=SMALL, test_episodes=2, seed=4,
                       ceiling=True)
    assert out.arms == ['stock', 'diagnosed', 'combination', 'independent', 'robot_trained']
    assert out.same_as == {'combination': 'stock'}      # the stock simulator is the paper's
    episodes = transfer.episode_seeds(4, 3, 2).reshape(-1)
    tests = [c for c in reality.calls if np.array_equal(c, episodes)]
    assert len(tests) == 4                             # stock, diagnosed, independent, robot
    block = transfer_stats.block(out)
    assert set(block) >= KEPT | ADDED
    assert block['status'] == 'complete' and block['trials'] == 3
    # reality is the stock simulator: its controllers score the same in both, to the bit
    assert block['fitness_gap_before'] == 0.0
    assert block['real_fitness_before'] == block['arms']['stock']['real']['mean']
    assert block['real_fitness_after'] == block['arms']['diagnosed']['real']['mean']
    assert block['arms']['combination']['real'] == block['arms']['stock']['real']
    assert 'versus_stock' not in block['arms']['combination']
    assert block['arms']['robot_trained']['sim'] is None
    assert block['real_fitness_robot_trained'] == block['arms']['robot_trained']['real']['mean']
    for name in ('diagnosed', 'independent', 'robot_trained'):
        v = block['arms'][name]['versus_stock']
        assert v['ci_low'] <= v['difference'] <= v['ci_high']
        assert v['verdict'] in transfer_stats.VERDICTS
    assert 'robot_trained' in transfer_report.markdown(block)


def test_bests_are_chosen_by_retest_and_do_not_depend_on_the_other_arms():
    assert transfer.EA.best == 'retest' and transfer.EA.retest_episodes == 5
    assert (transfer.EA.population, transfer.EA.generations) == (25, 50)
    sims = simulators()
    alone = transfer.run({'stock': sims['stock']}, Recorder(), trials=2, ea=SMALL,
                         test_episodes=1, seed=9)
    together = transfer.run(sims, Recorder(), trials=2, ea=SMALL, test_episodes=1, seed=9)
    assert np.array_equal(alone.bests['stock'], together.bests['stock'])
    # the best is the re-test winner: the same runs choosing their luckiest evaluation
    # pick other controllers
    luckiest = transfer.evolve(transfer.SimEvaluator(sims['stock']),
                               transfer.seeds_for(9, 'stock', 'evolve'), 2,
                               dataclasses.replace(SMALL, best='ever'))
    assert not np.array_equal(luckiest, together.bests['stock'])
    manual = [evolution.SteadyStateEA(SMALL, int(s)) for s in
              transfer.seeds_for(9, 'stock', 'evolve').generate_state(2)]
    evolution.evolve(manual, transfer.SimEvaluator(sims['stock']))
    assert np.array_equal(np.stack([e.best_genome for e in manual]), together.bests['stock'])
    # controllers evolved elsewhere with the same settings are used as given
    given = transfer.run(sims, Recorder(), trials=2, ea=SMALL, test_episodes=1, seed=9,
                         evolved={'stock': together.bests['stock']})
    assert np.array_equal(given.real['stock'], together.real['stock'])


def test_a_robot_that_stops_answering_keeps_what_was_measured():
    with pytest.raises(transfer.Stopped) as stop:
        transfer.run(simulators(), Recorder(fail_at=1), trials=2, ea=SMALL, test_episodes=1)
    out = stop.value.outcome
    assert '/dev/ttyUSB1' in str(stop.value) and '\n' not in str(stop.value)
    assert list(out.real) == ['stock'] and set(out.bests) >= {'stock', 'diagnosed'}
    block = transfer_stats.block(out)
    assert block['status'] == 'stopped' and '/dev/ttyUSB1' in block['error']
    assert block['stopped_at'] == 'testing the diagnosed controllers on the robot'
    assert block['real_fitness_before'] is not None and block['real_fitness_after'] is None
    assert block['recommended'] is None and not block['arms']['diagnosed']['tested']


def test_bad_settings_are_refused_naming_them():
    with pytest.raises(ValueError, match='at least 2 trials'):
        transfer.run(simulators(), Recorder(), trials=1)
    with pytest.raises(ValueError, match="needs a 'stock' arm"):
        transfer.run({'diagnosed': SimConfig()}, Recorder())


def test_verdicts_come_from_the_interval_with_the_power_of_a_null():
    rng = np.random.default_rng(0)
    stock = 0.6 + 0.02 * rng.standard_normal(10)
    assert transfer_stats.versus(stock + 0.1, stock)['verdict'] == 'better'
    assert transfer_stats.versus(stock - 0.1, stock)['verdict'] == 'worse'
    null = transfer_stats.versus(stock[::-1] + 0.001, stock)
    assert null['verdict'] == 'no detectable difference'
    assert 0.01 < null['mdd'] < 0.1 and f"{null['mdd']:.3f}" in null['text']


def test_the_share_recovered_is_of_the_distance_to_the_robot_trained_arm():
    rng = np.random.default_rng(1)
    stock = 0.5 + 0.02 * rng.standard_normal(10)
    robot = stock + 0.2 + 0.01 * rng.standard_normal(10)
    half = 0.6 + 0.02 * rng.standard_normal(10)
    s = transfer_stats.share(stock, half, robot)
    assert s['ci_low'] < s['share'] < s['ci_high']
    distance = robot.mean() - stock.mean()
    assert s['share'] == pytest.approx((half.mean() - stock.mean()) / distance)
    assert 0.3 < s['share'] < 0.7
    flat = transfer_stats.share(stock, half, stock[::-1])
    assert flat['ci_low'] is None                      # no distance: no interval


def test_do_no_harm_rejects_a_diagnosed_simulator_whose_controllers_do_worse():
    rng = np.random.default_rng(2)
    stock = 0.6 + 0.03 * rng.standard_normal(10)

    def decided(diagnosed):
        arms = {'stock': {'tested': True},
                'diagnosed': {'tested': True,
                              'versus_stock': transfer_stats.versus(diagnosed, stock)}}
        return transfer_stats.recommendation(arms)
    worse = decided(stock - 0.2)
    assert worse['recommended'] is False and worse['verdict'] == 'worse'
    slightly = decided(stock[::-1] - 0.005)     # below, not significantly: still not
    assert slightly['recommended'] is False
    assert slightly['verdict'] == 'no detectable difference'
    assert decided(stock[::-1] + 0.005)['recommended'] is True
    assert 'rejected' in transfer_report.recommendation_line({**worse, 'trials': 10})
