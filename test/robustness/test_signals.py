"""SIGINT and SIGTERM stop every long command cleanly, with what it finished saved.

The issue asks for a stop within 2 s; the assertion allows 10 s (a loaded CI machine)
and each measured time is printed (``pytest -s``)."""
from __future__ import annotations

import json
import re
import signal
import time

import numpy as np
import pytest
import yaml

from khepera_noise_ros.testing.domains import next_domain_id
from khepera_noise_ros.testing.processes import command, kill, opened, start, stop, wait_until

TINY = {'trials': 2, 'test_episodes': 2, 'phase1': {'population': 4, 'generations': 40},
        'phase2': {'population': 3, 'generations': 10}, 'task': {'steps': 10},
        'reality': {'robots': 4}}
LIMIT_S = 10.0


def replicate(tmp_path):
    tiny = tmp_path / 'tiny.yaml'
    tiny.write_text(yaml.safe_dump(TINY))
    out = tmp_path / 'rep'
    return (command('replicate', '--config', str(tiny), '--out', str(out), '--no-progress'),
            lambda pid: any(out.glob('units/**/*.json')),
            lambda: (out / 'sessions.json').is_file() and any(out.glob('units/**/*.json'))
            and not json.loads((out / 'sessions.json').read_text())['sessions'][-1]['finished'])


def graph_evolve(tmp_path):
    checkpoint = tmp_path / 'g.checkpoint.json'
    return (command('graph-evolve', '--population', '6', '--generations', '2000', '--steps',
                    '10', '--results', str(tmp_path / 'g.json'), '--log-level', 'warn'),
            lambda pid: checkpoint.is_file(),
            lambda: json.loads(checkpoint.read_text())['generation'] >= 0)


def evolve(tmp_path):
    partial = tmp_path / 'e.partial.json'
    bar = tmp_path / 'stderr.log'               # its progress bar: a generation done
    return (command('evolve', '--population', '6', '--generations', '100000', '--steps', '10',
                    '--out', str(tmp_path / 'e.json')),
            lambda pid: re.search(r'\| *[1-9][0-9]*/100000', bar.read_text()),
            lambda: json.loads(partial.read_text())['trials'][0]['history'])


def emulate(tmp_path):
    return (command('emulate', '--robots', '2', '--link', str(tmp_path / 'khepera')),
            lambda pid: (tmp_path / 'khepera1').is_symlink(),
            lambda: not list(tmp_path.glob('khepera*')))      # its links removed


def record(tmp_path):
    earlier = tmp_path / 'rec.csv'
    earlier.write_text('an earlier recording\n')
    # stopped, it keeps the episodes it finished: 5 conditions x 8 headings of 30 paced
    # samples each take about 12 s, so a stop after the second leaves some undone
    headings = ['0', '45', '90', '135', '180', '225', '270', '315']
    return (command('record', str(tmp_path / 'rec'), '--robot', 'emulator', '--samples',
                    '30', '--pace', '--period', '0.01', '--no-bag', '--headings', *headings),
            lambda pid: opened(pid, '/dev/ptmx') and time.sleep(2) is None,  # recording
            lambda: _finished_episodes_saved(tmp_path / 'rec', 30, 5 * len(headings)))


def _finished_episodes_saved(path, samples: int, planned: int) -> bool:
    from khepera_noise_ros.recording import read_csv
    rec = read_csv(path)
    episodes = np.unique(rec.episode)
    return (rec.manifest.get('interrupted') is True and 0 < episodes.size < planned
            and len(rec) == episodes.size * samples)


COMMANDS = {'replicate': replicate, 'graph-evolve': graph_evolve, 'evolve': evolve,
            'emulate': emulate, 'record': record}


@pytest.mark.parametrize('how', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
@pytest.mark.parametrize('name', sorted(COMMANDS))
def test_a_signal_stops_the_command_cleanly_with_its_results_saved(name, how, tmp_path):
    args, running, saved = COMMANDS[name](tmp_path)
    log = tmp_path / 'stderr.log'
    with open(log, 'w') as stderr:
        proc = start(args, next_domain_id(), stderr=stderr)
    try:
        assert wait_until(lambda: proc.poll() is not None or running(proc.pid), 90)
        assert proc.poll() is None, f'{name} ended early: {log.read_text()[-2000:]}'
        code, seconds = stop(proc, how, LIMIT_S)
        print(f'\n{name}: {signal.Signals(how).name} -> exit {code} in {seconds:.2f} s')
        assert code is not None, f'{name} still running {LIMIT_S} s after {how!r}'
        proc.communicate(timeout=30)
        err = log.read_text()
        assert code in (0, 130), err[-2000:]
        assert 'Traceback' not in err, err[-3000:]
        assert saved(), f'{name}: its partial results were not saved'
    finally:
        kill(proc)
