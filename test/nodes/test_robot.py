"""The simulator as a robot node: lockstep protocol, resends, bad messages, parameters,
unmodelled effects, and a backend that fails."""
import json
from pathlib import Path
import termios

import numpy as np
import pytest
from std_msgs.msg import Float64MultiArray, Int32MultiArray, MultiArrayDimension

from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.core.task import Episodes, Task, step_fitness
from khepera_noise_ros import simconfig
from khepera_noise_ros import effects as fx
from khepera_noise_ros.effects.simulate import EffectEpisodes
from khepera_noise_ros.nodes import protocol
from khepera_noise_ros.nodes.evolution_manager import EvolutionManager
from khepera_noise_ros.nodes.runtime import spinning
from khepera_noise_ros.nodes.params import overrides
from khepera_noise_ros.nodes.protocol import BEARING, CMD_TURN, EPISODE_START, FITNESS, \
    LIGHT
from khepera_noise_ros.nodes.simulator import Simulator
from khepera_noise_ros.reality.khepera_robot import RobotUnreachable
from khepera_noise_ros.testing.probe import Probe, controller, simulator, valid, wait_for

CONFIG = Path(__file__).resolve().parents[2] / 'config'
SEEDS = [11, 12, 13]


def turn(episode, step, direction, power):
    return protocol.pack_cmd_turn(episode, step, np.asarray(direction), np.asarray(power))


def test_lockstep_steps_only_on_the_current_command(ros_context):
    """Each reading equals the core's for the same seeds and commands; stale, future and
    other-episode commands are counted and change nothing; the end is a bearing and the
    episode's fitness, scored as core.task.run scores it."""
    sim = simulator(ros_context, steps=3, resend_timeout_s=60.0)
    probe = Probe(ros_context)
    commands = [([1, -1, 1], [3, 9, 0]), ([-1, -1, 1], [1, 2, 5]), ([1, 1, 1], [9, 9, 9])]
    core = Episodes(noise=NoiseModel(), task=Task(steps=3))
    expected = [core.reset(np.array(SEEDS), 3).copy()]
    expected_bearing = [core.bearing_deg.copy()]
    score = np.zeros(3, np.float32)
    for direction, power in commands:
        score += step_fitness(core.readings, np.array(power))
        readings = core.step(direction, power)
        expected.append(None if readings is None else readings.copy())
        expected_bearing.append(core.bearing_deg.copy())
    with spinning([sim, probe], ros_context):
        assert probe.connected(EPISODE_START) and probe.connected(CMD_TURN)
        probe.publish(EPISODE_START, protocol.pack_episode_start(7, SEEDS))
        (first,) = probe.wait_light(7, 0)
        np.testing.assert_array_equal(first.values, expected[0])

        probe.publish(CMD_TURN, turn(7, 1, *commands[1]))            # from the future
        probe.publish(CMD_TURN, turn(8, 0, *commands[0]))            # another episode
        probe.publish(CMD_TURN, turn(7, 0, [1, 1], [1, 1]))         # two robots, not three
        assert wait_for(lambda: sum(sim.dropped.values()) == 3)
        for step, (direction, power) in enumerate(commands):
            probe.publish(CMD_TURN, turn(7, step, direction, power))
            if step + 1 < len(commands):
                (light,) = probe.wait_light(7, step + 1)
                np.testing.assert_array_equal(light.values, expected[step + 1])
        assert wait_for(lambda: any(protocol.unpack_bearing(m).step == 3
                                    for m in probe.messages(BEARING)))
        probe.publish(CMD_TURN, turn(7, 0, *commands[0]))            # a late duplicate
        assert wait_for(lambda: sim.dropped['stale'] == 1)

    assert dict(sim.dropped) == {'future': 1, 'other_episode': 1, 'wrong_robots': 1,
                                 'stale': 1}
    lights = [protocol.unpack_light(m) for m in probe.messages(LIGHT)]
    assert [(b.episode, b.step) for b in lights] == [(7, 0), (7, 1), (7, 2)]
    bearings = {b.step: b.values[:, 0]
                for b in map(protocol.unpack_bearing, probe.messages(BEARING))}
    assert sorted(bearings) == [0, 1, 2, 3]
    for step, bearing in bearings.items():
        np.testing.assert_array_equal(bearing, expected_bearing[step])
    (fitness,) = {(b.episode, b.step, tuple(b.values[:, 0]))
                  for b in map(protocol.unpack_fitness, probe.messages(FITNESS))}
    assert fitness[:2] == (7, 3) and score.min() > 0
    np.testing.assert_array_equal(fitness[2], (score / np.float32(3)).astype(np.float64))


def test_a_lost_command_gets_the_light_resent_with_the_same_tag(ros_context):
    sim = simulator(ros_context, steps=5, resend_timeout_s=0.05)
    probe = Probe(ros_context)
    with spinning([sim, probe], ros_context):
        assert probe.connected(EPISODE_START)
        probe.publish(EPISODE_START, protocol.pack_episode_start(3, [5]))
        copies = probe.wait_light(3, 0, copies=3)                     # nobody answered
        for copy in copies[1:]:
            np.testing.assert_array_equal(copy.values, copies[0].values)
        probe.publish(CMD_TURN, turn(3, 0, [1], [2]))
        probe.wait_light(3, 1)
        probe.publish(EPISODE_START, protocol.pack_episode_start(3, [5]))   # duplicate start
        assert wait_for(lambda: sim.dropped['duplicate_start'] == 1)
    assert (sim.episode, sim.step_index) == (3, 1)


def test_malformed_messages_are_dropped_and_the_nodes_keep_running(ros_context):
    sim = simulator(ros_context, steps=4, resend_timeout_s=60.0)
    ctrl = controller(ros_context, genomes=[0.1] * 20)
    probe = Probe(ros_context)
    bad_length = protocol.pack_light(1, 0, np.full((1, 8), 100.0))
    bad_length.layout.dim[0] = MultiArrayDimension(label='robots', size=2, stride=16)
    nan_light = protocol.pack_light(1, 0, np.full((1, 8), 100.0))
    nan_light.data[5] = float('nan')
    bad_power = Int32MultiArray(data=[4, 0, 1, 12])
    protocol._layout(bad_power, 1, 2, 'turn', 2)
    bad_direction = turn(4, 0, [0], [3])
    nan_seed = protocol.pack_episode_start(4, [1.0])
    nan_seed.data[1] = float('nan')
    with spinning([sim, ctrl, probe], ros_context):
        assert probe.connected(LIGHT) and probe.connected(CMD_TURN, 2)
        assert probe.connected(EPISODE_START)
        for msg in (bad_length, nan_light):
            probe.publish(LIGHT, msg)
        probe.publish(LIGHT, protocol.pack_light(1, 0, np.full((2, 8), 100.0)))   # 2 robots
        for msg in (bad_power, bad_direction):
            probe.publish(CMD_TURN, msg)
        probe.publish(EPISODE_START, nan_seed)
        probe.publish(EPISODE_START, Float64MultiArray(data=[1.0, 2.0, 3.0]))      # no layout
        assert wait_for(lambda: ctrl.dropped['malformed'] == 2 and ctrl.dropped['wrong_robots']
                        == 1 and sim.dropped['malformed'] == 4)
        assert not [m for m in probe.messages(CMD_TURN) if m.data[0] == 1]     # no answer
        probe.publish(EPISODE_START, protocol.pack_episode_start(4, [9]))   # still working
        for step in range(4):
            probe.wait_light(4, step)
            assert wait_for(lambda: any(b.step == step for b in valid(
                probe.messages(CMD_TURN), protocol.unpack_cmd_turn) if b.episode == 4))
        assert wait_for(lambda: sim.backend.done)


def _correlation(messages) -> float:
    """Correlation of sensors 2 and 3 over every robot and message."""
    readings = np.concatenate([protocol.unpack_light(m).values for m in messages])
    return float(np.corrcoef(readings[:, 2], readings[:, 3])[0, 1])


def test_runtime_noise_change_shows_in_the_readings_and_bad_values_are_refused(ros_context):
    """Real-time mode, robots held still facing the lamp: only the noise moves the readings."""
    sim = simulator(ros_context, noise_model='independent', independent_level=0.05,
                    robots=200, perturbation_deg=0.0, rate_hz=100.0, steps=1000)
    probe = Probe(ros_context)
    with spinning([sim, probe], ros_context):
        results = probe.set_parameters('simulator', mode='realtime')
        assert results[0].successful
        assert wait_for(lambda: probe.count(LIGHT) >= 12)
        independent = _correlation(probe.messages(LIGHT)[2:12])

        results = probe.set_parameters('simulator', noise_model='combination',
                                       dependent_level=0.08, independent_level=0.01)
        assert all(r.successful for r in results)
        seen = probe.count(LIGHT)
        assert wait_for(lambda: probe.count(LIGHT) >= seen + 12)
        combination = _correlation(probe.messages(LIGHT)[seen + 2:seen + 12])

        refused = probe.set_parameters('simulator', noise_model='gaussian')
        refused += probe.set_parameters('simulator', dependence_groups='0,1,2;2,3')
        refused += probe.set_parameters('simulator', independent_level=1.5)
        refused += probe.set_parameters('simulator', deg_per_power=0.25)
        seen = probe.count(LIGHT)
        assert wait_for(lambda: probe.count(LIGHT) >= seen + 5)        # still publishing

    assert abs(independent) < 0.15 and combination > 0.9, (independent, combination)
    assert [r.successful for r in refused] == [False] * 4
    assert "noise_model must be one of ('none', 'independent', 'combination')" \
        in refused[0].reason
    assert 'overlap' in refused[1].reason
    assert refused[2].reason and 'multiple of 0.1' in refused[3].reason
    assert sim.get_parameter('noise_model').value == 'combination'
    assert sim.get_parameter('dependence_groups').value == '0,1,2,3,4,5;6,7'
    assert sim.backend.noise.model_noise == NoiseModel('combination', 0.08, 0.01)


@pytest.mark.parametrize('condition, model, dependent, independent', [
    ('ind5', 'independent', 0.0, 0.05), ('comb5', 'combination', 0.03, 0.02),
    ('ind10', 'independent', 0.0, 0.10), ('comb10', 'combination', 0.05, 0.05)])
def test_parameter_files_of_the_paper_conditions(ros_context, condition, model, dependent,
                                                 independent):
    args = ['--ros-args', '--params-file', str(CONFIG / f'sim_{condition}.yaml')]
    nodes = [simulator(ros_context, cli_args=args), controller(ros_context, cli_args=args),
             EvolutionManager(context=ros_context, cli_args=args)]
    try:
        sim, _, mgr = nodes
        assert sim.backend.noise.model_noise == NoiseModel(model, dependent, independent)
        assert sim.task == Task()          # the files hold the calibrated defaults
        assert mgr.get_parameter('results_path').value == f'results_sim_{condition}.json'
        assert mgr.get_parameter('phase').value == 1
    finally:
        for node in nodes:
            node.destroy_node()


def test_a_bad_parameter_file_stops_the_node_with_the_reason(ros_context, tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('/**/simulator:\n  ros__parameters:\n    dependence_groups: "0,1;1,2"\n'
                   '/**/controller:\n  ros__parameters:\n    genomes: [0.5, 1.0]\n')
    args = ['--ros-args', '--params-file', str(bad)]
    with pytest.raises(ValueError, match='must not overlap'):
        simulator(ros_context, cli_args=args)
    with pytest.raises(ValueError, match='multiple of 20'):
        controller(ros_context, cli_args=args)


def test_realtime_applies_the_latest_command_on_each_tick(ros_context):
    """Held facing the lamp (no perturbation), each robot turns only when a command came:
    these networks always say right at power 9, a 27 degree turn."""
    genome = np.zeros(20)
    genome[18:20] = 10.0                                   # output biases: right, power 9
    sim = simulator(ros_context, mode='realtime', rate_hz=40.0, robots=2, steps=1000,
                    perturbation_deg=0.0)
    ctrl = controller(ros_context, genomes=np.tile(genome, 2).tolist())
    probe = Probe(ros_context)
    with spinning([sim, ctrl, probe], ros_context):
        assert wait_for(lambda: probe.count(BEARING) >= 12)
    bearings = list(map(protocol.unpack_bearing, probe.messages(BEARING)))
    steps = [b.step for b in bearings]
    assert steps == list(range(steps[0], steps[0] + len(steps)))
    turns = np.diff(np.stack([b.values[:, 0] for b in bearings]), axis=0) % 360
    assert set(np.round(turns, 6).ravel()) <= {0.0, 27.0}
    assert (turns == 27.0).sum() >= turns.size // 2


def still_episode(probe: Probe, episode: int, seeds, steps: int) -> np.ndarray:
    """Run a lockstep episode whose robots never turn; its (steps, B, 8) readings."""
    probe.publish(EPISODE_START, protocol.pack_episode_start(episode, seeds))
    readings = []
    for step in range(steps):
        (light,) = probe.wait_light(episode, step)
        readings.append(light.values)
        probe.publish(CMD_TURN, turn(episode, step, [1] * len(seeds), [0] * len(seeds)))
    return np.stack(readings)


def core_still(seeds, steps: int, effects=()) -> np.ndarray:
    env = EffectEpisodes(task=Task(steps=steps), effects=effects)
    out, readings = [], env.reset(np.array(seeds))
    while readings is not None:
        out.append(readings.copy())
        readings = env.step(np.ones(len(seeds), int), np.zeros(len(seeds), int))
    return np.stack(out)


def test_a_fitted_effect_in_the_params_file_acts_in_the_simulator(ros_context, tmp_path):
    """The params file diagnose writes (the configuration plus the fitted effect, here one
    step of latency on sensors 0 and 1) makes those sensors read one step late; clearing
    ``effects`` while an episode runs changes the readings from the next episode."""
    latency = fx.SensorLatency((0, 1), 1)
    path = simconfig.write(simconfig.SimConfig(task=Task(steps=6)).with_effects(latency),
                           tmp_path / 'fitted_params.yaml')
    sim = simulator(ros_context, cli_args=['--ros-args', '--params-file', str(path)],
                    resend_timeout_s=60.0)
    probe = Probe(ros_context)
    with spinning([sim, probe], ros_context):
        assert probe.connected(EPISODE_START) and probe.connected(CMD_TURN)
        lagged = still_episode(probe, 1, SEEDS, 3)
        refused = probe.set_parameters('simulator', effects=json.dumps(
            [{'name': 'sensor_latency', 'sensors': [8], 'steps': 1}]))
        cleared = probe.set_parameters('simulator', effects='')       # mid-episode
        for step in range(3, 6):                                      # the rest of episode 1
            (light,) = probe.wait_light(1, step)
            lagged = np.concatenate([lagged, light.values[None]])
            probe.publish(CMD_TURN, turn(1, step, [1] * 3, [0] * 3))
        plain = still_episode(probe, 2, SEEDS, 6)

    core = core_still(SEEDS, 6)
    np.testing.assert_array_equal(lagged[1:, :, :2], core[:-1, :, :2])    # one step late
    np.testing.assert_array_equal(lagged[0], core[0])                     # the first repeats
    np.testing.assert_array_equal(lagged[:, :, 2:], core[:, :, 2:])
    np.testing.assert_array_equal(lagged, core_still(SEEDS, 6, (latency,)))
    np.testing.assert_array_equal(plain, core)
    assert not refused[0].successful and 'sensors [8]' in refused[0].reason
    assert cleared[0].successful and sim.backend.effects == ()


class FailingEpisodes(Episodes):
    """Core episodes whose robots fail at step ``at``, in the way ``how`` names."""

    def __init__(self, how: str, at: int, **kwargs):
        super().__init__(**kwargs)
        self.how, self.at = how, at

    def step(self, direction, power):
        readings = super().step(direction, power)
        if self.step_index != self.at:
            return readings
        if self.how == 'nan':
            readings[3, 0] = np.nan
            return readings
        raise {'unreachable': RobotUnreachable('robot 0 does not answer'),
               'termios': termios.error(5, 'Input/output error')}[self.how]


@pytest.mark.parametrize('how', ['unreachable', 'termios', 'nan'])
def test_a_failing_backend_ends_the_episode_and_nothing_of_it_is_resent(ros_context, how):
    sim = Simulator(context=ros_context, backend=FailingEpisodes(how, 2, task=Task(steps=5)),
                    parameter_overrides=overrides(Simulator.parameter_specs(), {
                        'steps': 5, 'resend_timeout_s': 0.02}))
    probe = Probe(ros_context)
    with spinning([sim, probe], ros_context):
        assert probe.connected(EPISODE_START) and probe.connected(CMD_TURN)
        probe.publish(EPISODE_START, protocol.pack_episode_start(3, SEEDS))
        for step in range(2):
            probe.wait_light(3, step)
            probe.publish(CMD_TURN, turn(3, step, [1, 1, 1], [2, 2, 2]))
        assert wait_for(lambda: sim.episode is None)                   # the robots failed
        probe.publish(CMD_TURN, turn(3, 2, [1, 1, 1], [2, 2, 2]))      # late, for it
        assert wait_for(lambda: sim.dropped['other_episode'] == 1)
        probe.publish(EPISODE_START, protocol.pack_episode_start(4, SEEDS))
        probe.wait_light(4, 0, copies=5)             # still running, and resending again
        tags = [tuple(m.data[:2]) for m in probe.messages(LIGHT)]     # valid or not
    assert tags.count((3, 1)) == 1 and (3, 2) not in tags          # never resent, never sent
