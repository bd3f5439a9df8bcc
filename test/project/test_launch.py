"""The launch files: installed with the package; loaded where ROS 2's launch is installed
(it has no wheel on PyPI, so elsewhere those tests are skipped with the reason)."""
import importlib.util
from pathlib import Path
import py_compile
import subprocess
import sys

import pytest

ROOT = Path(__file__).resolve().parents[2]
LAUNCH_FILES = sorted((ROOT / 'launch').glob('*.launch.py'))
NO_LAUNCH = 'ROS 2 launch/launch_ros are not installed (no PyPI wheel): source a ROS 2 install'


def test_every_launch_file_is_installed_by_setup_py(tmp_path):
    """setup.py's data_files put launch/*.launch.py in share/khepera_noise_ros/launch, where
    colcon build installs them and ros2 launch looks."""
    subprocess.run([sys.executable, 'setup.py', '-q', 'install_data', '-d', str(tmp_path)],
                   cwd=ROOT, check=True, capture_output=True)
    installed = sorted(p.name for p in (tmp_path / 'share/khepera_noise_ros/launch').iterdir())
    assert installed == [p.name for p in LAUNCH_FILES]
    assert {'simulation.launch.py', 'workers.launch.py', 'bridge.launch.py'} <= set(installed)


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_launch_files_compile(path):
    py_compile.compile(str(path), doraise=True)


def load(path: Path):
    spec = importlib.util.spec_from_file_location(path.stem.replace('.', '_'), path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.generate_launch_description()


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_launch_descriptions_load(path):
    pytest.importorskip('launch_ros', reason=NO_LAUNCH)
    pytest.importorskip('ament_index_python')
    from launch import LaunchDescription
    description = load(path)
    assert isinstance(description, LaunchDescription)
    assert description.entities


def test_the_workers_launch_starts_n_pairs_and_a_manager_that_uses_them():
    pytest.importorskip('launch_ros', reason=NO_LAUNCH)
    from launch import LaunchContext
    from launch.actions import OpaqueFunction
    description = load(ROOT / 'launch/workers.launch.py')
    context = LaunchContext()
    context.launch_configurations.update({'workers': '3', 'params_file': 'p.yaml'})
    (opaque,) = [e for e in description.entities if isinstance(e, OpaqueFunction)]
    nodes = opaque.execute(context)
    assert len(nodes) == 4


def test_launch_files_keep_the_style():
    from ament_flake8.main import main_with_errors
    rc, errors = main_with_errors(argv=[str(p) for p in LAUNCH_FILES])
    assert rc == 0, '\n'.join(errors)
