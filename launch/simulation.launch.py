"""The simulation graph: simulator, controller and evolution_manager, one process each.

    ros2 launch khepera_noise_ros simulation.launch.py params_file:=<a config/*.yaml>

Every node reads its own section of the one params file (the installed
config/sim_comb5.yaml by default: the paper's 5% combination noise).
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

PACKAGE = 'khepera_noise_ros'


def generate_launch_description() -> LaunchDescription:
    default = os.path.join(get_package_share_directory(PACKAGE), 'config', 'sim_comb5.yaml')
    params = LaunchConfiguration('params_file')
    return LaunchDescription([
        DeclareLaunchArgument('params_file', default_value=default,
                              description='ROS 2 params file with a section per node'),
        Node(package=PACKAGE, executable='simulator', name='simulator', parameters=[params]),
        Node(package=PACKAGE, executable='controller', name='controller'),
        Node(package=PACKAGE, executable='evolution_manager', name='evolution_manager',
             parameters=[params]),
    ])
