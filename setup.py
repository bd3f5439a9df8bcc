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
    ],
    python_requires='>=3.10',
    install_requires=['setuptools', 'numpy', 'scipy', 'matplotlib', 'pyyaml', 'pyserial',
                      'tqdm'],
    extras_require={
        # ROS 2 from PyPI wheels, for machines without a sourced ROS 2 install.
        'wheels': ['ros-rclpy[fastrtps]', 'ros-std-msgs', 'ros-sensor-msgs'],
        # rosbag2 (MCAP) recordings without the ROS C++ stack.
        'bags': ['rosbags'],
        'test': ['pytest', 'rosbags', 'flake8', 'ros-ament-flake8', 'hypothesis'],
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
