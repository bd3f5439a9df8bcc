"""The documentation as a user meets it: a short README that starts with the set-up
commands CI runs, parameter tables generated from the descriptors, links that resolve,
and no citation of a file outside the repository."""
from pathlib import Path
import re

import pytest

from khepera_noise_ros.core.frames import sensor_poses
from khepera_noise_ros.effects import REGISTRY
from khepera_noise_ros.tools import effect_docs, param_docs

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / 'README.md'
INSTALL = "python3 -m venv .venv && .venv/bin/pip install -q -e '.[wheels,test]'"
COMMANDS = [f'{INSTALL} && .venv/bin/khepera-noise replicate --quick',
            f'{INSTALL} && .venv/bin/python -m pytest -q']
# pages other branches write; until they are merged the link check cannot run
ELSEWHERE: set[str] = set()
MINE = ('model.md', 'nodes.md', 'parameters.md', 'distributed.md', 'reality.md',
        'recordings.md', 'benchmarks.md', 'design.md')


def pages() -> list[Path]:
    return [README] + sorted((ROOT / 'docs').rglob('*.md'))


def test_the_readme_is_a_front_door_that_starts_with_the_two_commands():
    text = README.read_text()
    assert len(text.splitlines()) <= 300
    commands = [line for line in text.splitlines() if line.startswith('python3 -m venv')]
    assert commands[:2] == COMMANDS
    first_block = text.split('```')[1]
    assert all(c in first_block for c in COMMANDS)


def test_ci_runs_the_readme_test_command_verbatim():
    assert COMMANDS[1] in (ROOT / '.ci' / 'run').read_text().splitlines()


def test_parameter_docs_are_the_generated_ones():
    assert (ROOT / 'docs' / 'parameters.md').read_text() == param_docs.render(), \
        'run: python -m khepera_noise_ros.tools.param_docs'
    assert param_docs.main(['--check']) == 0


def test_every_parameter_of_every_node_is_documented():
    text = (ROOT / 'docs' / 'parameters.md').read_text()
    for _, specs, _ in param_docs.SECTIONS:
        for spec in specs:
            assert f'| `{spec.name}` |' in text
            assert spec.description.replace('|', '\\|') in text


def test_every_docs_page_of_this_branch_exists():
    for name in MINE:
        assert (ROOT / 'docs' / name).is_file(), name


def test_nothing_cites_a_file_outside_the_repository():
    """Neither the docs nor the code point at the team's design notes or a path outside."""
    pattern = re.compile(r'DESIGN\.md|STYLE\.md|/work/|\.\./shared|shared/DESIGN')
    skipped = {'.venv', '.git', 'build', 'install'}
    files = [p for p in ROOT.rglob('*') if p.is_file() and p.suffix in (
        '.md', '.py', '.yaml', '.xml', '.cfg', '.txt') and not skipped & set(p.parts)]
    assert len(files) > 50
    cited = [f'{p.relative_to(ROOT)}:{n}' for p in files if p != Path(__file__)
             for n, line in enumerate(p.read_text(errors='replace').splitlines(), 1)
             if pattern.search(line)]
    assert not cited, cited


def test_relative_links_resolve():
    missing = []
    for page in pages():
        for target in re.findall(r'\]\(([^)#\s]+)(?:#[^)]*)?\)', page.read_text()):
            if re.match(r'[a-z]+://', target):
                continue
            if not (page.parent / target).exists():
                missing.append((page.relative_to(ROOT), target))
    unmerged = {t for _, t in missing if Path(t).name in ELSEWHERE}
    assert not [m for m in missing if Path(m[1]).name not in ELSEWHERE], missing
    if unmerged:
        pytest.skip(f'pages written on other branches are not merged yet: {sorted(unmerged)}')


def test_the_sensor_pose_table_is_the_code_s():
    text = (ROOT / 'docs' / 'nodes.md').read_text()
    for n, pose in enumerate(sensor_poses()):
        row = (f'| s{n} | `{pose.frame}` | {pose.x:.4f} | {pose.y:.4f} | '
               f'{round(pose.yaw * 180 / 3.141592653589793)} |')
        assert row.replace('-0.0000', '0.0000') in text, row


def test_the_effect_catalogue_is_the_generated_one():
    assert (ROOT / 'docs' / 'effects.md').read_text() == effect_docs.render(), \
        'run: python -m khepera_noise_ros.tools.effect_docs'
    assert effect_docs.main(['--check']) == 0


def test_the_catalogue_names_every_registered_effect_and_parameter():
    text = (ROOT / 'docs' / 'effects.md').read_text()
    for name, cls in REGISTRY.items():
        assert f'## `{name}`' in text and cls.summary in text
        for field, spec in cls.params().items():
            assert f'| `{field}` |' in text and spec.doc in text, (name, field)
