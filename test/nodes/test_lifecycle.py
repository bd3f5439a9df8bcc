"""hardware_bridge as a managed node, against the robot emulator on pseudo-terminals:
configure opens and checks the ports, activate serves, deactivate stops the motors,
cleanup closes the ports."""
import numpy as np
from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rclpy.parameter import Parameter

from khepera_noise_ros.nodes import protocol
from khepera_noise_ros.nodes.runtime import spinning
from khepera_noise_ros.nodes.hardware_bridge import FAILURE, SUCCESS, HardwareBridge
from khepera_noise_ros.nodes.params import overrides
from khepera_noise_ros.reality.emulator import Emulator
from khepera_noise_ros.reality.world import EmulatedWorld
from khepera_noise_ros.testing.probe import TIMEOUT, Listener, Probe, wait_for


def bridge(context, ports, **values):
    values = {'ports': list(ports), 'steps': 50, 'timeout_s': 1.0, 'retries': 1, **values}
    return HardwareBridge(context=context, parameter_overrides=overrides(
        HardwareBridge.parameter_specs(), values))


def state(node) -> str:
    return node._state_machine.current_state[1]


def opened(node) -> list[bool]:
    return [link._serial is not None for link in node.backend.bodies.links]


def call(probe, srv_type, name, request):
    client = probe.create_client(srv_type, name)
    assert client.wait_for_service(TIMEOUT)
    future = client.call_async(request)
    assert wait_for(future.done), f'no answer from {name}'
    return future.result()


def test_the_bridge_goes_through_its_lifecycle(ros_context):
    with Emulator(EmulatedWorld(seed=1, robots=2)) as em:
        node = bridge(ros_context, em.ports)
        probe = Probe(ros_context)
        with spinning([node, probe], ros_context):
            assert state(node) == 'unconfigured' and opened(node) == [False, False]
            assert probe.connected(protocol.EPISODE_START)
            probe.publish(protocol.EPISODE_START, protocol.pack_episode_start(1, [3, 4]))
            assert wait_for(lambda: node.dropped['inactive'] == 1)

            # configure as a lifecycle manager would, through the node's service
            answer = call(probe, ChangeState, '/hardware_bridge/change_state',
                          ChangeState.Request(transition=Transition(
                              id=Transition.TRANSITION_CONFIGURE)))
            assert answer.success and state(node) == 'inactive'
            assert opened(node) == [True, True]
            assert [em.served(r)['B'] for r in (0, 1)] == [1, 1]       # each robot answered
            probe.publish(protocol.EPISODE_START, protocol.pack_episode_start(1, [3, 4]))
            assert wait_for(lambda: node.dropped['inactive'] == 2)    # configured, not active
            assert not probe.messages(protocol.LIGHT)

            assert node.trigger_activate() == SUCCESS and state(node) == 'active'
            probe.publish(protocol.EPISODE_START, protocol.pack_episode_start(2, [3, 4]))
            probe.wait_light(2, 0)
            assert node.episode == 2

            for robot in em.robots:                         # a motor left running
                robot.speeds[:] = (5.0, -5.0)
            stops = [em.served(r)['D'] for r in (0, 1)]
            assert node.trigger_deactivate() == SUCCESS and state(node) == 'inactive'
            assert [em.served(r)['D'] for r in (0, 1)] == [s + 1 for s in stops]
            assert all(not robot.speeds.any() for robot in em.robots)
            assert node.episode is None

            assert node.trigger_cleanup() == SUCCESS and state(node) == 'unconfigured'
            assert opened(node) == [False, False]

            assert node.trigger_configure() == SUCCESS and node.trigger_activate() == SUCCESS
            probe.publish(protocol.EPISODE_START, protocol.pack_episode_start(3, [3, 4]))
            (light,) = probe.wait_light(3, 0)
            assert light.values.shape == (2, 8) and np.all(light.values <= 525)
            got = call(probe, GetState, '/hardware_bridge/get_state', GetState.Request())
            assert got.current_state.id == State.PRIMARY_STATE_ACTIVE


def test_configure_fails_on_a_port_without_a_robot_and_the_node_stays(ros_context, tmp_path):
    missing = str(tmp_path / 'ttyNOTHING')
    with Emulator(EmulatedWorld(seed=1, robots=1)) as em:
        node = bridge(ros_context, [em.ports[0], missing], timeout_s=0.05, retries=0)
        try:
            assert node.trigger_configure() == FAILURE
            assert state(node) == 'unconfigured' and opened(node) == [False, False]
            # the node is alive: it takes parameters and configures with a good port
            assert node.set_parameters([Parameter('ports', value=em.ports[:1])])[0].successful
            assert node.trigger_configure() == SUCCESS and opened(node) == [True]
        finally:
            node.destroy_node()


def test_autostart_configures_and_activates(ros_context):
    with Emulator(EmulatedWorld(seed=1, robots=1)) as em:
        node = bridge(ros_context, em.ports, autostart=True)
        try:
            assert state(node) == 'active' and node.serving and opened(node) == [True]
        finally:
            node.destroy_node()
        assert em.served(0)['B'] == 1


def test_the_active_bridge_publishes_illuminance_of_unknown_variance(ros_context):
    """The bridge's conventional view: robot 0's readings in their sensor frames, variance
    0 (unknown: there is no noise model of the real robot)."""
    with Emulator(EmulatedWorld(seed=2, robots=2)) as em:
        node = bridge(ros_context, em.ports, autostart=True)
        probe, listener = Probe(ros_context), Listener(ros_context, namespace='/')
        with spinning([node, probe, listener], ros_context):
            assert probe.connected(protocol.EPISODE_START)
            assert wait_for(node.view.wanted)
            probe.publish(protocol.EPISODE_START, protocol.pack_episode_start(5, [1, 2]))
            (light,) = probe.wait_light(5, 0)
            assert wait_for(lambda: len(listener.steps()) == 1)
            (messages,) = listener.steps().values()
    assert [m.header.frame_id for m in messages] == [f'light_sensor_{n}' for n in range(8)]
    assert [m.illuminance for m in messages] == list(525.0 - light.values[0])
    assert [m.variance for m in messages] == [0.0] * 8
