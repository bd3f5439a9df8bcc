"""package.xml and setup.py declare what the code imports from ROS."""
import ast
from pathlib import Path
import re
import sys

ROOT = Path(__file__).resolve().parents[2]
ROS = re.compile(r'^(rclpy|launch|launch_ros|ament_index_python|\w+_(msgs|srvs|interfaces))$')


def imported_ros_packages() -> set[str]:
    found = set()
    for path in list((ROOT / 'khepera_noise_ros').rglob('*.py')) + list(
            (ROOT / 'launch').glob('*.py')):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module] if isinstance(node, ast.ImportFrom) and node.module \
                and not node.level else []
            found |= {n.split('.')[0] for n in names if ROS.match(n.split('.')[0])}
    return found


def test_every_imported_ros_package_is_declared_in_package_xml():
    imported = imported_ros_packages()
    assert {'rclpy', 'rcl_interfaces', 'std_msgs', 'sensor_msgs', 'geometry_msgs',
            'diagnostic_msgs', 'std_srvs', 'tf2_msgs', 'launch'} <= imported
    declared = set(re.findall(r'<(?:exec_|build_|test_)?depend>([\w-]+)</',
                              (ROOT / 'package.xml').read_text()))
    assert imported <= declared, sorted(imported - declared)


def test_the_wheels_extra_brings_every_imported_ros_package_that_has_a_wheel():
    setup = (ROOT / 'setup.py').read_text()
    no_wheel = {'tf2_msgs', 'launch', 'launch_ros', 'ament_index_python'}
    for package in imported_ros_packages() - no_wheel:
        assert f"'ros-{package.replace('_', '-')}" in setup, package
        assert package in sys.modules or __import__(package)
