"""The record command: driving robot nodes over the lockstep topics into recordings."""
import json
import time

import numpy as np
import pytest
from std_msgs.msg import Float64MultiArray

from khepera_noise_ros import cli
from khepera_noise_ros.commands import record as record_command
from khepera_noise_ros.nodes.recorder import Recorder
from khepera_noise_ros.core.evaluation import CoreEvaluator
from khepera_noise_ros.core.khepera import World
from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.core.task import Episodes, Task
from khepera_noise_ros.recording import load, write_csv


def parse(*argv):
    return cli.build_parser().parse_args(['record', *map(str, argv)])


def core_stationary(world: World, seed: int, heading: float, samples: int) -> np.ndarray:
    env = Episodes(world, NoiseModel(), Task(steps=samples, perturbation_deg=0))
    readings, rows = env.reset([seed], 1, bearing_deg=heading), []
    while readings is not None:
        rows.append(readings[0])
        readings = env.step([1], [0])
    return np.array(rows)


def test_stationary_recording_of_the_simulator_is_the_core_s_readings(ros_context, tmp_path):
    args = parse(tmp_path / 'r', '--conditions', 'bulb_1ft,room_dark', '--headings', 0, 25,
                 '--samples', 8, '--seed', 3)
    rec, session = record_command.record(args, context=ros_context)
    conditions = record_command.named_conditions()
    assert rec.conditions() == ['bulb_1ft', 'room_dark'] and len(rec) == 32
    assert rec.manifest['conditions'] == {c: conditions[c] for c in ('bulb_1ft', 'room_dark')}
    assert rec.manifest['noise']['noise_model'] == 'combination'
    assert rec.manifest['lost_steps'] == [] and rec.step_problems() == ([], [])
    assert np.isnan(rec.direction).all() and np.isnan(rec.power).all()
    for episode, (label, heading) in enumerate([('bulb_1ft', 0), ('bulb_1ft', 25),
                                                ('room_dark', 0), ('room_dark', 25)]):
        rows = rec.episode == episode
        assert set(rec.condition[rows]) == {label}
        np.testing.assert_array_equal(rec.heading_deg[rows], heading)
        world = World(**conditions[label])
        np.testing.assert_array_equal(rec.readings[rows],
                                      core_stationary(world, 3 + episode, heading, 8))
    write_csv(rec, tmp_path / 'r')
    assert load(tmp_path / 'r').manifest['protocol'] == 'stationary'


def test_closed_loop_recording_is_the_core_s_trace(ros_context, tmp_path):
    genome = np.random.default_rng(7).uniform(-2, 2, 20)
    (tmp_path / 'g.json').write_text(json.dumps(genome.tolist()))
    args = parse(tmp_path / 'c', '--protocol', 'closed-loop', '--genome', tmp_path / 'g.json',
                 '--episodes', 2, '--steps', 12, '--seed', 5)
    rec, _ = record_command.record(args, context=ros_context)
    assert rec.manifest['genome'] == pytest.approx(genome.tolist())
    evaluator = CoreEvaluator(task=Task(steps=12))
    for episode in range(2):
        trace = evaluator.trace(genome[None], [5 + episode])
        rows = rec.episode == episode
        np.testing.assert_array_equal(rec.readings[rows], trace.readings[:, 0])
        np.testing.assert_array_equal(rec.heading_deg[rows], trace.bearing_deg[:, 0])
        np.testing.assert_array_equal(rec.direction[rows], trace.direction[:, 0])
        np.testing.assert_array_equal(rec.power[rows], trace.power[:, 0])


def test_duplicated_readings_are_answered_but_kept_once(ros_context):
    """A second publisher repeats every light message; each step is still recorded once."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    from khepera_noise_ros.nodes import protocol
    from khepera_noise_ros.nodes.simulator import Simulator
    from rclpy.parameter import Parameter
    robot = Simulator(context=ros_context, parameter_overrides=[
        Parameter('perturbation_deg', value=0.0), Parameter('steps', value=6)])
    echo = Node('echo', context=ros_context)
    repeat = echo.create_publisher(Float64MultiArray, protocol.LIGHT, protocol.QOS)

    def echo_light(msg):
        if msg.layout.dim[0].label == 'sensors':         # not our own echo
            repeat.publish(_relabelled(msg))
    echo.create_subscription(Float64MultiArray, protocol.LIGHT, echo_light, protocol.QOS)
    node = Node('recorder', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    try:
        for n in (robot, echo, node):
            executor.add_node(n)
        recorder = Recorder(node, timeout_s=5.0)
        recorder.wait_for_robot(executor, 10.0)
        deadline = time.monotonic() + 10
        while repeat.get_subscription_count() < 2 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        log = recorder.record_episode(executor, 0, 11, 6, record_command.hold_still, 0.0)
    finally:
        executor.shutdown()
        for n in (robot, echo, node):
            n.destroy_node()
    assert sorted(log.light) == list(range(6)) and log.lost == []
    assert recorder.resent >= 5
    np.testing.assert_array_equal(np.array([log.light[s] for s in range(6)]),
                                  core_stationary(World(), 11, 0.0, 6))


def _relabelled(msg):
    """The same reading again, marked so the echo does not echo itself."""
    copy = Float64MultiArray()
    copy.layout.dim = list(msg.layout.dim)
    copy.layout.data_offset = msg.layout.data_offset
    copy.data = msg.data
    first = msg.layout.dim[0]
    copy.layout.dim[0] = type(first)(label='echo', size=first.size, stride=first.stride)
    return copy


class FailsAtStep:
    """A simulated robot whose episode breaks down after ``fail_at`` steps."""

    def __init__(self, fail_at: int):
        self.env, self.fail_at = Episodes(task=Task(perturbation_deg=0)), fail_at

    def __getattr__(self, name):
        return getattr(self.env, name)

    def __setattr__(self, name, value):
        if name == 'task':
            self.env.task = value
        else:
            super().__setattr__(name, value)

    def reset(self, seed, robots=None, bearing_deg=None):
        return self.env.reset(seed, robots, bearing_deg)

    def step(self, direction, power):
        if self.env.step_index + 1 == self.fail_at:
            raise RuntimeError('the robot fell over')
        return self.env.step(direction, power)


def test_lost_steps_are_reported_and_declared(ros_context, tmp_path):
    from khepera_noise_ros.nodes.robot_node import RobotNode
    robot = RobotNode('fragile', backend=FailsAtStep(4), context=ros_context)
    try:
        args = parse(tmp_path / 'lost', '--conditions', 'task', '--samples', 7, '--timeout',
                     0.6)
        rec, _ = record_command.record(args, context=ros_context, robot=robot)
        # the session's settings are undone: the node is left as it was found
        assert robot.get_parameter('steps').value == 60
        assert robot.get_parameter('perturbation_deg').value == Task().perturbation_deg
    finally:
        robot.destroy_node()
    assert rec.step.tolist() == [0, 1, 2, 3]
    assert rec.manifest['lost_steps'] == [[0, 4], [0, 5], [0, 6]]
    write_csv(rec, tmp_path / 'lost')
    assert load(tmp_path / 'lost').manifest['lost_steps'] == [[0, 4], [0, 5], [0, 6]]


def test_bridge_recording_replays_into_the_analysis_unchanged(tmp_path, capsys):
    """The emulator behind the hardware bridge (serial over a pty), under two of section 2's
    conditions: the bag and the CSV read back the same, every step once, and equal a
    recording of the emulator's world without the serial link."""
    common = ['--conditions', 'bulb_2ft,room_dark', '--samples', '12', '--seed', '4']
    assert cli.main(['record', str(tmp_path / 'bridge'), '--robot', 'emulator'] + common) == 0
    assert '24 samples in 2 episodes; 0 resent readings kept once; 0 steps lost' in \
        capsys.readouterr().out
    assert cli.main(['record', str(tmp_path / 'world'), '--robot', 'emulator-world',
                     '--no-bag'] + common) == 0
    from_bag, from_csv = load(tmp_path / 'bridge_bag'), load(tmp_path / 'bridge.csv')
    direct = load(tmp_path / 'world')
    assert from_bag.manifest['source'] == 'emulator' and 'noise' not in from_bag.manifest
    assert from_bag.step_problems() == ([], [])
    for name in ('episode', 'step', 'heading_deg', 'readings'):
        np.testing.assert_array_equal(getattr(from_bag, name), getattr(from_csv, name))
        np.testing.assert_array_equal(getattr(from_bag, name), getattr(direct, name))
    assert from_bag.conditions() == ['bulb_2ft', 'room_dark']
    assert not (tmp_path / 'world_bag').exists()
    # the emulator's room flicker: the dark room's adjacent sensors move together
    assert cli.main(['synchrony', str(tmp_path / 'bridge_bag'), '--resamples', '100']) == 0
    saved = json.loads((tmp_path / 'bridge_synchrony' / 'synchrony.json').read_text())
    dark = from_bag.readings[from_bag.condition == 'room_dark']
    assert saved['conditions'][1]['pairs'][0]['r'] == pytest.approx(
        np.corrcoef(dark[:, 2], dark[:, 3])[0, 1])
    assert saved['conditions'][1]['pairs'][0]['r'] > 0.9


def test_usage_errors(tmp_path, capsys):
    assert cli.main(['record', str(tmp_path / 'x'), '--attach', '/robot']) == 2
    assert '--attach needs --source' in capsys.readouterr().err
    assert cli.main(['record', str(tmp_path / 'x'), '--protocol', 'closed-loop']) == 2
    assert 'needs --genome' in capsys.readouterr().err
    with pytest.raises(ValueError, match=r"unknown condition\(s\) \['moonlight'\]"):
        record_command.parse_conditions('bulb_1ft,moonlight')
