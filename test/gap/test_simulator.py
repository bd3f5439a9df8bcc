"""The simulator side of the diagnosis: fitted effects in a params file the simulator node
loads (the transfer experiment: test/experiment/test_transfer.py)."""
from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.effects import (ActuatorTurnError, CorrelatedNoise, SensorGainOffset,
                                       TemporalDrift)
from khepera_noise_ros import simconfig


def test_effects_and_parameters_round_trip_through_a_params_file(tmp_path):
    effects = (CorrelatedNoise(((0, 1), (5, 6, 7)), 0.02),
               SensorGainOffset((3,), (1.1,), (-4.0,)), ActuatorTurnError(0.8, 0.1))
    config = simconfig.SimConfig(noise=NoiseModel('combination', 0.05, 0.01, ((0, 1, 2),)),
                                 effects=effects)
    simconfig.write(config, tmp_path / 'p.yaml')
    assert simconfig.load(tmp_path / 'p.yaml') == config


def test_the_simulator_node_loads_the_written_params_file(tmp_path, ros_context):
    from khepera_noise_ros.nodes.simulator import Simulator
    config = simconfig.SimConfig(noise=NoiseModel('combination', 0.045, 0.015, ((2, 3),),
                                                  'normal'),
                                 effects=(TemporalDrift((0, 1), 0.01, 20.0),))
    path = simconfig.write(config, tmp_path / 'fitted.yaml')
    node = Simulator(context=ros_context, cli_args=['--ros-args', '--params-file', str(path)])
    try:
        values = {k: node.get_parameter(k).value for k in simconfig.NOISE_KEYS}
        effects = node.get_parameter('effects').value
    finally:
        node.destroy_node()
    assert values == {'noise_model': 'combination', 'dependent_level': 0.045,
                      'independent_level': 0.015, 'dependence_groups': '2,3',
                      'distribution': 'normal', 'rounding': 'level'}
    assert simconfig.from_parameters({'effects': effects}).effects == config.effects
