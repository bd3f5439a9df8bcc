"""The simulator side: effects in the core's episodes, params files, the transfer experiment."""
import numpy as np
import pytest

from khepera_noise_ros.core import network, task
from khepera_noise_ros.core.evolution import EAConfig
from khepera_noise_ros.core.khepera import World
from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.gap import effects as fx
from khepera_noise_ros.gap import simconfig, transfer
from khepera_noise_ros.gap.simulate import EffectEpisodes
from test_gap_support import GENOME


def _run(env, seeds) -> np.ndarray:
    weights = network.unpack(np.repeat(np.array(GENOME)[None], len(seeds), axis=0))
    out, readings = [], env.reset(seeds)
    while readings is not None:
        out.append(readings.copy())
        readings = env.step(*network.act(weights, readings))
    return np.stack(out)


def test_without_effects_the_episodes_are_the_cores():
    seeds = np.arange(6)
    assert np.array_equal(_run(EffectEpisodes(), seeds), _run(task.Episodes(), seeds))


def _still(env, seeds) -> np.ndarray:
    """Readings of robots that never turn (the heading changes only by the knocks)."""
    out, readings = [], env.reset(seeds)
    while readings is not None:
        out.append(readings.copy())
        readings = env.step(np.ones(len(seeds), int), np.zeros(len(seeds), int))
    return np.stack(out)


def test_latency_delays_readings_and_survives_a_new_noise_model():
    seeds = np.arange(3)
    plain = _still(task.Episodes(noise=NoiseModel('none')), seeds)
    env = EffectEpisodes(noise=NoiseModel('none'), effects=(fx.SensorLatency((0, 1), 1),))
    env.reset(seeds)
    env.noise = NoiseModel('none')                 # as a node does on a parameter change
    assert len(env.noise.reading) == 1
    lagged = _still(env, seeds)
    assert np.array_equal(lagged[1:, :, :2], plain[:-1, :, :2])      # one step late
    assert np.array_equal(lagged[0, :, :2], plain[0, :, :2])         # the first repeats
    assert np.array_equal(lagged[:, :, 2:], plain[:, :, 2:])


def test_effects_and_parameters_round_trip_through_a_params_file(tmp_path):
    effects = (fx.CorrelatedNoise(((0, 1), (5, 6, 7)), 0.02),
               fx.SensorGainOffset((3,), (1.1,), (-4.0,)), fx.ActuatorTurnError(0.8, 0.1))
    config = simconfig.SimConfig(noise=NoiseModel('combination', 0.05, 0.01, ((0, 1, 2),)),
                                 effects=effects)
    simconfig.write(config, tmp_path / 'p.yaml')
    assert simconfig.load(tmp_path / 'p.yaml') == config


def test_the_simulator_node_loads_the_written_params_file(tmp_path):
    from conftest import ros_domain
    from khepera_noise_ros.nodes.simulator import Simulator
    config = simconfig.SimConfig(noise=NoiseModel('combination', 0.045, 0.015, ((2, 3),),
                                                  'normal'),
                                 effects=(fx.TemporalDrift((0, 1), 0.01, 20.0),))
    path = simconfig.write(config, tmp_path / 'fitted.yaml')
    with ros_domain(['--ros-args', '--params-file', str(path)]) as context:
        node = Simulator(context=context)
        values = {k: node.get_parameter(k).value for k in simconfig.NOISE_KEYS}
        node.destroy_node()
    assert values == {'noise_model': 'combination', 'dependent_level': 0.045,
                      'independent_level': 0.015, 'dependence_groups': '2,3',
                      'distribution': 'normal', 'rounding': 'level'}


def test_transfer_gap_is_zero_when_reality_is_the_simulator_and_reported_both_ways():
    config = simconfig.SimConfig(noise=NoiseModel.independent_only(0.02))
    reality = transfer.SimEvaluator(config, World())
    calls = []

    def real(genomes, seeds):
        calls.append(len(seeds))
        return reality(genomes, seeds)
    out = transfer.run(config, World(), [fx.ActuatorTurnError(0.5, 0.0)], real, trials=2,
                       ea=EAConfig(population=4, generations=2), test_episodes=3)
    assert calls == [6, 6]
    assert out['fitness_gap_before'] == pytest.approx(0.0, abs=1e-6)
    assert out['fitness_gap_after'] != pytest.approx(0.0, abs=1e-6)
    assert out['trials'] == 2
    assert set(out) >= {'fitness_gap_before', 'fitness_gap_after', 'trials', 'gap_p'}
    with pytest.raises(ValueError, match='at least 2 trials'):
        transfer.run(config, World(), [], real, trials=1)
