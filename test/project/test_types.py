"""Types: the packages listed here pass ``mypy`` with the settings of setup.cfg's [mypy]
section (strict); a type error fails the suite with mypy's own report."""
from __future__ import annotations

from pathlib import Path
import subprocess
import sys

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ['khepera_noise_ros/core', 'khepera_noise_ros/effects', 'khepera_noise_ros/gap',
            'khepera_noise_ros/recording', 'khepera_noise_ros/files.py',
            'khepera_noise_ros/memo.py',             'khepera_noise_ros/simconfig.py']


def mypy(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'mypy', *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)


def test_the_typed_packages_pass_mypy_strict():
    done = mypy(*PACKAGES)
    assert done.returncode == 0, done.stdout + done.stderr


def test_mypy_reads_the_strict_settings_and_reports_an_error(tmp_path):
    bad = tmp_path / 'untyped.py'
    bad.write_text('def double(x):\n    return 2 * x\n')
    done = mypy('--config-file', str(ROOT / 'setup.cfg'), str(bad))
    assert done.returncode == 1
    assert 'Function is missing a type annotation  [no-untyped-def]' in done.stdout
