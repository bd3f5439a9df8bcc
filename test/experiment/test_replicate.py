"""`khepera-noise replicate` end to end at a tiny scale: through the node graph and the
hardware bridge to the emulator, against the same run in process."""
import json
import re

import pytest
import yaml

from khepera_noise_ros.testing.domains import next_domain_id
from khepera_noise_ros import cli
from khepera_noise_ros.commands import replicate
from khepera_noise_ros.experiment.protocol import STEPS

TINY = {'trials': 2, 'test_episodes': 2, 'phase1': {'population': 4, 'generations': 2},
        'phase2': {'population': 3, 'generations': 1}, 'task': {'steps': 10},
        'reality': {'robots': 6}}


@pytest.fixture
def tiny(tmp_path, monkeypatch):
    monkeypatch.setenv('ROS_DOMAIN_ID', str(next_domain_id()))
    path = tmp_path / 'tiny.yaml'
    path.write_text(yaml.safe_dump(TINY))
    return path


def scores(out) -> dict:
    units = json.loads((out / 'results.json').read_text())['units']
    return {(u['condition'], u['trial'], u['step']): u.get('best_fitness', u.get('mean'))
            for u in units}


def test_the_graph_and_the_bridge_give_the_in_process_numbers(tiny, tmp_path, monkeypatch):
    served = []

    class Recorded(replicate.EmulatorProcess):
        def __exit__(self, *exc):
            super().__exit__(*exc)
            served.extend(self.served(r) for r in range(len(self.ports)))

    monkeypatch.setattr(replicate, 'EmulatorProcess', Recorded)
    graph, core = tmp_path / 'graph', tmp_path / 'core'
    assert cli.main(['replicate', '--config', str(tiny), '--out', str(graph),
                     '--no-progress']) == 0
    assert cli.main(['replicate', '--config', str(tiny), '--out', str(core), '--backend', 'core',
                     '--no-progress']) == 0
    assert len(scores(graph)) == 4 * 2 * len(STEPS)
    assert scores(graph) == scores(core)          # bit for bit: same seeds, same physics
    # reality went through the serial protocol: every robot read its sensors and turned
    assert len(served) == TINY['reality']['robots']
    assert all(s['O'] > 0 and s['C'] > 0 for s in served)
    text = (graph / 'report.md').read_text()
    assert 'the node graph' in text and 'through the hardware bridge node' in text
    written = yaml.safe_load((graph / 'config.yaml').read_text())
    assert written['backend'] == {'simulation': 'graph', 'reality': 'emulator'}
    assert written['dependence_groups'] == [[0, 1, 2, 3, 4, 5], [6, 7]]


def test_port_makes_the_robots_on_those_ports_reality(tiny, tmp_path):
    """--port: here the ports are an emulator's, set up as the default run sets up its own."""
    from khepera_noise_ros.experiment import config as settings
    config = settings.load(tiny)
    world = replicate._world(config)
    from khepera_noise_ros.reality.emulator import Emulator
    with Emulator(world) as emulator:
        ports = sum((['--port', p] for p in emulator.ports), [])
        assert cli.main(['replicate', '--config', str(tiny), '--out', str(tmp_path / 'hw'),
                         '--no-progress', '--backend', 'core', *ports]) == 0
        assert all(emulator.served(r)['O'] > 0 for r in range(len(emulator.ports)))
    assert cli.main(['replicate', '--config', str(tiny), '--out', str(tmp_path / 'core'),
                     '--backend', 'core', '--no-progress']) == 0
    assert scores(tmp_path / 'hw') == scores(tmp_path / 'core')
    written = yaml.safe_load((tmp_path / 'hw' / 'config.yaml').read_text())
    assert written['backend'] == {'simulation': 'core', 'reality': 'hardware'}


def test_a_rerun_resumes_and_other_settings_are_refused(tiny, tmp_path, capsys):
    out = tmp_path / 'run'
    args = ['replicate', '--config', str(tiny), '--out', str(out), '--backend', 'core',
            '--no-progress']
    assert cli.main(args) == 0
    before = scores(out)
    assert cli.main(args) == 0
    assert '40 finished units and 0 evolutions part-way' in capsys.readouterr().err
    assert scores(out) == before
    sessions = json.loads((out / 'results.json').read_text())['sessions']
    assert [s['finished'] for s in sessions] == [True, True]
    assert cli.main(args + ['--seed', '7']) == 2
    assert 'other settings' in capsys.readouterr().err
    assert cli.main(args + ['--seed', '7', '--fresh']) == 0
    assert scores(out) != before


def test_a_killed_run_saves_its_evolutions_part_way(tmp_path):
    """SIGTERM in the middle of phase 1: checkpoints on disk, and a rerun resumes from them."""
    import os
    import signal
    import subprocess
    import sys
    config = tmp_path / 'slow.yaml'
    config.write_text(yaml.safe_dump({**TINY, 'phase1': {'population': 10, 'generations': 400}}))
    out = tmp_path / 'out'
    command = [sys.executable, '-m', 'khepera_noise_ros.cli', 'replicate', '--config',
               str(config), '--out', str(out), '--backend', 'core']
    child = subprocess.Popen(command, stderr=subprocess.PIPE, env={**os.environ})
    seen = b''
    while not re.search(rb' gen [1-9]', seen):    # tqdm draws the generation on stderr
        chunk = child.stderr.read1(4096)
        assert chunk, f'the run ended early: {seen[-500:]!r}'
        seen += chunk
    child.send_signal(signal.SIGTERM)
    _, err = child.communicate(timeout=60)
    assert child.returncode == 130
    assert b'run the same command again to resume' in err
    parts = sorted((out / 'units').rglob('step1.checkpoint.json'))
    assert len(parts) == 4 * TINY['trials']
    assert all(len(json.loads(p.read_text())['told']) > 10 for p in parts)   # generation 1+
    assert not list((out / 'units').rglob('*.tmp'))


def test_both_protocols_run_side_by_side_when_asked(tiny, tmp_path, capsys):
    out = tmp_path / 'run'
    assert cli.main(['replicate', '--config', str(tiny), '--out', str(out), '--backend', 'core',
                     '--protocol', 'both', '--no-progress']) == 0
    printed = capsys.readouterr().out
    assert '--- protocol: measured' in printed and '--- protocol: paper' in printed
    measured = yaml.safe_load((out / 'config.yaml').read_text())
    paper = yaml.safe_load((tmp_path / 'run-paper' / 'config.yaml').read_text())
    assert (measured['protocol'], paper['protocol']) == ('measured', 'paper')
    assert paper['phase2']['best'] == 'ever' and paper['reality']['start_bearing_deg'] is None
    assert measured['phase2']['best'] == 'retest'
    # the preset comes first, the file after it: what the file sets holds in both
    assert measured['test_episodes'] == paper['test_episodes'] == TINY['test_episodes']
    assert (tmp_path / 'run-paper' / 'report.md').exists()
