"""The tests mirror the package: test/ has a folder per package (and one for the checks that
cut across it), and no test imports another test module, a conftest or a benchmark script,
nor edits sys.path to reach one; what tests share is in khepera_noise_ros/testing or a
conftest's fixtures."""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TEST = ROOT / 'test'
FOLDERS = {'core', 'effects', 'gap', 'nodes', 'reality', 'experiment', 'recording', 'commands',
           'robustness', 'project'}


def local_modules() -> set[str]:
    """The names a test could import another test file or a benchmark script by."""
    names = {p.stem for p in TEST.rglob('*.py')} | {'conftest'}
    names |= {p.stem for p in (ROOT / 'benchmark').rglob('*.py')}
    names |= {p.name for p in (ROOT / 'benchmark').iterdir() if p.is_dir()}
    return names | {'test', 'benchmark'} | FOLDERS


def offences(path: Path, local: set[str]) -> list[str]:
    """Each import of a test module, conftest or benchmark script in ``path``, and each use
    of sys.path, as 'line: what'."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            names = ['.' if node.level else node.module or '']
        elif isinstance(node, ast.Attribute) and node.attr == 'path' and \
                isinstance(node.value, ast.Name) and node.value.id == 'sys':
            names = ['sys.path']
        found += [f'{node.lineno}: {n}' for n in names
                  if n in ('.', 'sys.path') or n.split('.')[0] in local
                  or n.startswith('test_')]
    return found


def test_every_test_sits_in_a_folder_of_its_package():
    flat = {p.name for p in TEST.glob('*.py')} - {'conftest.py'}
    assert not flat, f'put these in a folder of test/: {sorted(flat)}'
    folders = {p.name for p in TEST.iterdir() if p.is_dir() and p.name != '__pycache__'}
    assert folders <= FOLDERS, f'a new folder of test/: add it to FOLDERS: {folders - FOLDERS}'
    package = {p.name for p in (ROOT / 'khepera_noise_ros').iterdir() if p.is_dir()}
    assert FOLDERS - {'robustness', 'project'} <= package


def test_no_test_imports_another_test_or_a_benchmark():
    local = local_modules()
    files = list(TEST.rglob('*.py'))
    assert len(files) > 40
    found = [f'{p.relative_to(ROOT)}:{o}' for p in files for o in offences(p, local)]
    assert not found, found


def test_an_import_of_a_test_module_or_a_benchmark_is_found(tmp_path):
    bad = tmp_path / 'test_x.py'
    bad.write_text('import sys\nsys.path.insert(0, "benchmark")\nfrom blind_gap import robot\n'
                   'from conftest import ros_domain\nfrom . import helpers\n'
                   'import test_recording\nimport numpy\n'
                   'from khepera_noise_ros.testing.probe import Probe\n')
    assert sorted(offences(bad, {'blind_gap', 'conftest', 'test_recording'})) == [
        '2: sys.path', '3: blind_gap', '4: conftest', '5: .', '6: test_recording']
