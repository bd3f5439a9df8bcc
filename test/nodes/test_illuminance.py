"""The conventional view of a robot node: sensor_msgs/Illuminance per light sensor,
received by a node that subscribes like any other."""
import numpy as np
import pytest
from rclpy.node import Node

from khepera_noise_ros.core.illuminance import illuminance_variance
from khepera_noise_ros.core.khepera import DARK
from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.nodes import protocol
from khepera_noise_ros.nodes.runtime import spinning
from khepera_noise_ros.testing.probe import Listener, Probe, simulator, wait_for


def test_a_realtime_simulator_publishes_illuminance_with_frames_stamps_and_variance(
        ros_context):
    """Each step's eight messages carry the sensor's frame, one stamp, 525 - reading of
    robot 0 (lux_per_count 2 doubles it) and the combination model's variance there."""
    noise = NoiseModel(dependent=0.05, independent=0.04)
    sim = simulator(ros_context, mode='realtime', rate_hz=50.0, robots=2, lux_per_count=2.0,
                    frame_prefix='k1/', dependent_level=0.05, independent_level=0.04)
    listener = Listener(ros_context)
    with spinning([sim, listener], ros_context):
        assert wait_for(lambda: len(listener.steps()) >= 5 and len(listener.light) >= 5)
        steps = listener.steps()
        readings = listener.robot0_light()
    matched = 0
    for stamp, messages in steps.items():
        assert stamp[0] > 0
        assert [m.header.frame_id for m in messages] == [
            f'k1/light_sensor_{n}' for n in range(8)]
        lux = np.array([m.illuminance for m in messages])
        reading = DARK - lux / 2.0
        assert any(np.array_equal(reading, r) for r in readings), 'no such light message'
        variance = np.array([m.variance for m in messages])
        np.testing.assert_allclose(variance, illuminance_variance(reading, noise, 2.0))
        assert (variance > 0).all()
        matched += 1
    assert matched >= 5


def test_in_lockstep_illuminance_is_published_only_while_someone_subscribes(ros_context):
    sim = simulator(ros_context, steps=3, resend_timeout_s=60.0)
    probe = Probe(ros_context)
    with spinning([sim, probe], ros_context):
        assert probe.connected(protocol.EPISODE_START)
        assert not sim.view.wanted()
        listener = Listener(ros_context, namespace='/')
        with spinning([listener], ros_context):
            assert wait_for(sim.view.wanted)
            probe.publish(protocol.EPISODE_START, protocol.pack_episode_start(4, [5, 6]))
            probe.wait_light(4, 0)
            assert wait_for(lambda: len(listener.steps()) == 1)
            (messages,) = listener.steps().values()
            (light,) = [b for b in map(protocol.unpack_light, probe.messages(protocol.LIGHT))
                        if b.episode == 4]
            np.testing.assert_array_equal([m.illuminance for m in messages],
                                          DARK - light.values[0])


def test_static_transforms_name_base_link_and_each_sensor_frame(ros_context, monkeypatch):
    """/tf_static needs tf2_msgs, which has no wheel: a stand-in TFMessage shows what the
    node would publish (geometry_msgs transforms, REP 105 names, REP 103 yaw)."""
    import math
    import sys
    import types

    from khepera_noise_ros.core.frames import sensor_poses
    from khepera_noise_ros.nodes.robot_view import static_transforms

    class TFMessage:
        def __init__(self, transforms):
            self.transforms = transforms
    fake = types.ModuleType('tf2_msgs')
    fake.msg = types.SimpleNamespace(TFMessage=TFMessage)
    monkeypatch.setitem(sys.modules, 'tf2_msgs', fake)
    monkeypatch.setitem(sys.modules, 'tf2_msgs.msg', fake.msg)
    node = Node('frames', context=ros_context)
    try:
        msg = static_transforms(node, 'r2/', 0.03, 0.01)
    finally:
        node.destroy_node()
    assert [t.header.frame_id for t in msg.transforms] == ['r2/base_link'] * 8
    assert [t.child_frame_id for t in msg.transforms] == [p.frame for p in sensor_poses('r2/')]
    for t, pose in zip(msg.transforms, sensor_poses('r2/', 0.03, 0.01)):
        assert (t.transform.translation.x, t.transform.translation.y,
                t.transform.translation.z) == (pose.x, pose.y, 0.01)
        yaw = 2 * math.atan2(t.transform.rotation.z, t.transform.rotation.w)
        assert yaw == pytest.approx(pose.yaw)


def test_without_tf2_msgs_there_are_no_static_transforms(ros_context, monkeypatch):
    import sys
    from khepera_noise_ros.nodes.robot_view import static_transforms
    monkeypatch.setitem(sys.modules, 'tf2_msgs', None)      # import fails
    node = Node('frames', context=ros_context)
    try:
        assert static_transforms(node, '', 0.03, 0.01) is None
    finally:
        node.destroy_node()
