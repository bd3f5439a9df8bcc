from glob import glob

from setuptools import find_packages, setup

package_name = 'khepera_noise_ros'
nodes = ['simulator', 'controller', 'evolution_manager', 'hardware_bridge', 'worker_pair']

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
    ],
    python_requires='>=3.10',
    install_requires=['setuptools', 'numpy', 'scipy', 'matplotlib', 'pyyaml', 'pyserial',
                      'tqdm'],
    extras_require={
        # ROS 2 from PyPI wheels, for machines without a sourced ROS 2 install: every
        # message and service package the nodes import (tf2_msgs and launch have no wheel).
        'wheels': ['ros-rclpy[fastrtps]', 'ros-std-msgs', 'ros-sensor-msgs',
                   'ros-geometry-msgs', 'ros-diagnostic-msgs', 'ros-std-srvs',
                   'ros-rcl-interfaces', 'ros-lifecycle-msgs'],
        # rosbag2 (MCAP) recordings without the ROS C++ stack.
        'bags': ['rosbags'],
        # statsmodels: an independent check of the power and TOST code (docs/statistics.md);
        # hypothesis: property tests of parsers and fitters; arch and allantools: reference
        # implementations the block-length rule and the Allan deviation are checked against;
        # pytest-xdist: the suite on every core; mypy (and the stubs of what it reads): the
        # type check test/project/test_types.py runs.
        'test': ['pytest', 'pytest-xdist', 'rosbags', 'flake8', 'ros-ament-flake8',
                 'statsmodels', 'hypothesis', 'arch', 'allantools', 'mypy', 'scipy-stubs',
                 'types-PyYAML'],
    },
    zip_safe=True,
    maintainer='khepera_noise_ros maintainers',
    maintainer_email='khepera-noise@example.org',
    description='Meeden (1998) sensor-noise models for evolving Khepera controllers in ROS 2',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [f'{n} = {package_name}.nodes.{n}:main' for n in nodes] + [
            f'khepera-noise = {package_name}.cli:main',
        ],
    },
)
