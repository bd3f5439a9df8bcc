"""N worker pairs (simulator + controller in one process each, namespaces /w0 ..) and
an evolution_manager that shares the evaluations among them.

    ros2 launch khepera_noise_ros workers.launch.py workers:=4 params_file:=<yaml>
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

PACKAGE = 'khepera_noise_ros'


def pairs(context) -> list:
    count = int(LaunchConfiguration('workers').perform(context))
    if count < 1:
        raise ValueError(f'workers must be at least 1, got {count}')
    params = LaunchConfiguration('params_file')
    # no name=: it would rename both nodes of the pair's process alike
    nodes = [Node(package=PACKAGE, executable='worker_pair', namespace=f'/w{i}',
                  parameters=[params]) for i in range(count)]
    nodes.append(Node(package=PACKAGE, executable='evolution_manager',
                      name='evolution_manager',
                      parameters=[params, {'workers': [f'/w{i}' for i in range(count)]}]))
    return nodes


def generate_launch_description() -> LaunchDescription:
    default = os.path.join(get_package_share_directory(PACKAGE), 'config', 'sim_comb5.yaml')
    return LaunchDescription([
        DeclareLaunchArgument('workers', default_value='2',
                              description='How many worker pairs to start'),
        DeclareLaunchArgument('params_file', default_value=default,
                              description='ROS 2 params file with a section per node'),
        OpaqueFunction(function=pairs),
    ])
