"""`diagnose --transfer-*` with the measured protocol (do no harm, a robot that stops, the
ports), and the diagnosed condition of `replicate` and `sweep` (--params)."""
import json
import os
from contextlib import contextmanager

import numpy as np
import pytest
import yaml

from khepera_noise_ros.testing.domains import next_domain_id
from khepera_noise_ros import cli, simconfig
from khepera_noise_ros import effects as fx
from khepera_noise_ros.commands import _transfer
from khepera_noise_ros.experiment import config as settings
from khepera_noise_ros.gap import diagnose
from khepera_noise_ros.reality.effects import EffectsConfig
from khepera_noise_ros.reality.emulator import EmulatorProcess
from khepera_noise_ros.reality.khepera_robot import InProcessRobots
from khepera_noise_ros.reality.world import EmulatedWorld
from khepera_noise_ros.reality import record as inprocess
from khepera_noise_ros.recording import write_csv

GENOME = np.array([0.9, -0.6, 0.5, -0.4, 0.7, 0.3, -0.8, 0.9, -0.5, 0.6, -0.9, -0.2, 2.5,
                   -1.5, -2.5, 1.0, 0.5, -0.5, 0.3, 0.2])
# the simulator believes turns do nothing: its controllers never learn to turn
HARMFUL = fx.ActuatorTurnError(scale=0.0, knocks=False)
BENIGN = fx.CorrelatedNoise(((0, 1, 2),), 0.003)
FAST = ['--effects', 'correlated_noise', '--replicates', '40', '--no-figures', '--no-progress',
        '--transfer-population', '6', '--transfer-generations', '4']


@pytest.fixture(scope='module')
def recorded(tmp_path_factory):
    """A small stationary and closed-loop recording of the emulated robot."""
    where = tmp_path_factory.mktemp('rec')
    robots = InProcessRobots(EmulatedWorld(EffectsConfig.real_robot(), seed=3, robots=1,
                                           start_bearing_deg=0.0))
    write_csv(inprocess.stationary(robots, names=('bulb_1ft', 'room_dark'), headings=(0, 30),
                                   samples=20), where / 'still')
    write_csv(inprocess.closed_loop(robots, GENOME, episodes=8), where / 'loop')
    return [str(where / 'still'), str(where / 'loop')]


def fitting(monkeypatch, effect):
    """The diagnosis as it is, but fitting ``effect`` (whatever it would have fitted)."""
    real = diagnose.diagnose

    class Fitted(diagnose.Diagnosis):
        @property
        def fitted_effects(self):
            return [effect]

    def patched(*args, **kwargs):
        result = real(*args, **kwargs)
        result.__class__ = Fitted
        return result
    monkeypatch.setattr(diagnose, 'diagnose', patched)


def test_a_harmful_fitted_effect_is_not_written_as_the_recommendation(
        recorded, tmp_path, monkeypatch, capsys):
    fitting(monkeypatch, HARMFUL)
    out = tmp_path / 'out'
    code = cli.main(['diagnose', *recorded, '--out', str(out), *FAST, '--transfer-emulator',
                     'real_robot', '--transfer-trials', '4', '--transfer-test-episodes', '3',
                     '--no-transfer-ceiling'])
    assert code == 0
    stdout = capsys.readouterr().out
    assert not (out / 'fitted_params.yaml').exists()
    rejected = out / 'fitted_params.rejected.yaml'
    assert rejected.read_text().startswith('# NOT RECOMMENDED: ')
    assert simconfig.load(rejected).effects == (HARMFUL,)
    data = json.loads((out / 'diagnosis.json').read_text())
    t = data['transfer']
    assert data['recommended'] is False and t['recommended'] is False
    assert t['real_fitness_after'] < t['real_fitness_before']
    assert data['recommendation'] == t['recommendation']
    assert 'fitted_params.rejected.yaml' in stdout
    assert 'Not recommended' in (out / 'report.md').read_text().splitlines()[2]
    assert '| diagnosed |' in (out / 'report.md').read_text()
    assert t['trials'] == 4 and t['test_episodes'] == 3 and t['ea']['best'] == 'retest'


def test_the_diagnose_defaults_are_the_measured_protocol(recorded):
    args = cli.build_parser().parse_args(['diagnose', *recorded, '--transfer-emulator',
                                          'real_robot'])
    assert (args.transfer_trials, args.transfer_test_episodes) == (10, 10)
    assert _transfer.ceiling(args) is True
    ports = cli.build_parser().parse_args(['diagnose', *recorded, '--transfer-port', 'X'])
    assert _transfer.ceiling(ports) is False
    assert _transfer.ea_of(ports).best == 'retest'


def test_transfer_port_tests_on_the_robots_there_and_a_robot_that_stops_is_named(
        recorded, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv('ROS_DOMAIN_ID', str(next_domain_id()))
    fitting(monkeypatch, BENIGN)
    real_robot = _transfer.robot
    with EmulatorProcess(EmulatedWorld(seed=4, robots=2, start_bearing_deg=0.0)) as emulator:
        # an open slave keeps each pty's number taken once the robots go: another worker's
        # new pty cannot take the name this command keeps retrying
        held = [os.open(port, os.O_RDWR | os.O_NOCTTY) for port in emulator.ports]
        calls = []

        @contextmanager
        def stopping(args, world, config):
            with real_robot(args, world, config) as (evaluate, where):
                def reality(genomes, seeds):
                    if len(calls) == 2:                # the robots go away after two tests
                        emulator.__exit__()
                    calls.append(len(seeds))
                    return evaluate(genomes, seeds)
                yield reality, where
        monkeypatch.setattr(_transfer, 'robot', stopping)
        out = tmp_path / 'out'
        try:
            code = cli.main(['diagnose', *recorded, '--out', str(out), *FAST,
                             '--transfer-port', *emulator.ports, '--transfer-trials', '2',
                             '--transfer-test-episodes', '2'])
        finally:
            for fd in held:
                os.close(fd)
    assert code == 1
    err = [line for line in capsys.readouterr().err.splitlines() if 'error:' in line]
    assert len(err) == 1 and emulator.ports[0] in err[0]
    assert 'tested on the robot: stock, diagnosed' in err[0]
    data = json.loads((out / 'diagnosis.json').read_text())
    t = data['transfer']
    assert t['status'] == 'stopped' and calls == [4, 4, 4]
    assert t['arms']['stock']['tested'] and t['arms']['diagnosed']['tested']
    assert len(t['arms']['stock']['values']['real']) == 2
    assert not t['arms']['independent']['tested']
    assert (out / 'fitted_params.yaml').exists() == bool(t['recommended'])


def _params(tmp_path, effects: str) -> str:
    path = tmp_path / 'fitted.yaml'
    path.write_text(yaml.safe_dump({'/**': {'ros__parameters': {
        'noise_model': 'independent', 'independent_level': 0.02, 'effects': effects}}}))
    return str(path)


def test_params_adds_a_diagnosed_condition_beside_the_papers_models(tmp_path):
    path = _params(tmp_path, fx.dumps([BENIGN]))
    plain = settings.load()
    with_it = settings.load(overrides={'diagnosed': path})
    names = [c.name for c in with_it.conditions]
    assert names == [c.name for c in plain.conditions] + ['diagnosed']
    assert with_it.diagnosed.effects == (BENIGN,)
    assert with_it.diagnosed.noise.model == 'independent'
    assert with_it.hash != plain.hash
    assert settings.build(dict(plain.data)).hash == plain.hash
    again = tmp_path / 'config.yaml'
    again.write_text(with_it.to_yaml())                # results' settings read back
    assert settings.load(again).hash == with_it.hash


@pytest.mark.parametrize('command', ['replicate', 'sweep'])
def test_a_bad_params_file_is_refused_in_one_line_naming_it(tmp_path, capsys, command):
    missing = str(tmp_path / 'nope.yaml')
    assert cli.main([command, '--params', missing, '--out', str(tmp_path / 'o')]) == 2
    err = capsys.readouterr().err.strip()
    assert '\n' not in err and 'nope.yaml' in err
    unknown = _params(tmp_path, json.dumps([{'name': 'wheel_wobble', 'scale': 2}]))
    assert cli.main([command, '--params', unknown, '--out', str(tmp_path / 'o')]) == 2
    err = capsys.readouterr().err.strip()
    assert '\n' not in err and "'wheel_wobble'" in err and 'fitted.yaml' in err
    assert all(name in err for name in fx.DEFAULT)      # the world model's parts too


def test_replicate_and_sweep_run_the_diagnosed_condition(tmp_path):
    tiny = tmp_path / 'tiny.yaml'
    tiny.write_text(yaml.safe_dump({
        'test_episodes': 2, 'task': {'steps': 10}, 'reality': {'robots': 6},
        'phase1': {'population': 4, 'generations': 2, 'retest_episodes': 2},
        'phase2': {'population': 3, 'generations': 1, 'retest_episodes': 2}}))
    path = _params(tmp_path, fx.dumps([fx.ActuatorTurnError(scale=0.5)]))
    out = tmp_path / 'rep'
    assert cli.main(['replicate', '--config', str(tiny), '--backend', 'core', '--trials', '2',
                     '--params', path, '--out', str(out), '--no-progress']) == 0
    report = (out / 'report.md').read_text()
    assert 'Does the diagnosed simulator transfer better?' in report
    rows = json.loads((out / 'results.json').read_text())['analysis']['diagnosed']['rows']
    assert {r['step'] for r in rows} == {2, 3, 5}
    assert {r['against'] for r in rows} == {'5% combination', '5% independent',
                                            '10% combination', '10% independent'}
    sweep_out = tmp_path / 'sweep'
    assert cli.main(['sweep', '--config', str(tiny), '--trials', '2', '--shares', '0',
                     '--levels', '0.05', '--no-control', '--params', path, '--out',
                     str(sweep_out), '--no-progress']) == 0
    point = json.loads((sweep_out / 'sweep.json').read_text())['points'][0]
    assert set(point['diagnosed']) >= {'5% combination step 3', '10% independent step 5'}
    assert 'diagnosed - 5% combination' in (sweep_out / 'sweep.md').read_text()
