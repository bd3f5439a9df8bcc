"""The hardware bridge (a managed node) with a controller: the bridge is configured
(ports opened and checked) and, once inactive, activated.

    ros2 launch khepera_noise_ros bridge.launch.py params_file:=<config/bridge.yaml>
"""
import os

from ament_index_python.packages import get_package_share_directory
import launch
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, RegisterEventHandler
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node
from launch_ros.event_handlers import OnStateTransition
from launch_ros.events.lifecycle import ChangeState
from lifecycle_msgs.msg import Transition

PACKAGE = 'khepera_noise_ros'


def generate_launch_description() -> LaunchDescription:
    default = os.path.join(get_package_share_directory(PACKAGE), 'config', 'bridge.yaml')
    bridge = LifecycleNode(package=PACKAGE, executable='hardware_bridge',
                           name='hardware_bridge', namespace='',
                           parameters=[LaunchConfiguration('params_file')])

    def transition(transition_id: int) -> EmitEvent:
        return EmitEvent(event=ChangeState(
            lifecycle_node_matcher=launch.events.matches_action(bridge),
            transition_id=transition_id))

    return LaunchDescription([
        DeclareLaunchArgument('params_file', default_value=default,
                              description='ROS 2 params file with a hardware_bridge section'),
        bridge,
        Node(package=PACKAGE, executable='controller', name='controller'),
        RegisterEventHandler(OnStateTransition(
            target_lifecycle_node=bridge, goal_state='inactive',
            entities=[transition(Transition.TRANSITION_ACTIVATE)])),
        transition(Transition.TRANSITION_CONFIGURE),
    ])
