"""The sweep over emulated realities: its points, refusals, output and resuming."""
import json

import numpy as np
import pytest
import yaml

from khepera_noise_ros import cli
from khepera_noise_ros.experiment import config as settings
from khepera_noise_ros.experiment import sweep
from khepera_noise_ros.reality.effects import EffectsConfig

TINY = {'test_episodes': 2, 'phase1': {'population': 4, 'generations': 2, 'retest_episodes': 2},
        'phase2': {'population': 3, 'generations': 1, 'retest_episodes': 2},
        'task': {'steps': 10}}


@pytest.fixture
def tiny_config(tmp_path):
    path = tmp_path / 'tiny.yaml'
    path.write_text(yaml.safe_dump(TINY))
    return path


def sweep_cli(tmp_path, config, *extra):
    return cli.main(['sweep', '--config', str(config), '--out', str(tmp_path / 'sweep'),
                     '--trials', '2', '--shares', '0,1', '--levels', '0.05', '--no-progress',
                     *extra])


def test_a_point_splits_its_noise_into_shared_and_own_parts():
    p = sweep.Point(0.75, 0.08, 'halves')
    e = p.effects(EffectsConfig.real_robot())
    assert e.sensor_noise == pytest.approx(0.02)
    assert e.correlated_noise.enabled and e.correlated_noise.location == ((0, 1, 2), (3, 4, 5),
                                                                          (6, 7))
    assert e.correlated_noise.strength == pytest.approx(0.06 / np.sqrt(3))
    assert not e.intensity_dependent_noise.enabled
    assert e.sensor_gain_offset == EffectsConfig.real_robot().sensor_gain_offset   # gap kept
    keys = [q.key for q in sweep.points({'shares': [0, 1], 'levels': [0.05, 0.1]})]
    assert len(keys) == 5 and keys[-1] == sweep.CONTROL and len(set(keys)) == 5


@pytest.mark.parametrize('spec, named', [
    ({'trials': -3}, '-3'), ({'shares': [0.5, 1.2]}, '1.2'), ({'levels': [-0.1]}, '-0.1'),
    ({'colour': 'red'}, 'colour'), ({'groupings': ['diagonal']}, 'diagonal'),
])
def test_bad_sweep_settings_are_refused_naming_the_value(spec, named):
    with pytest.raises(ValueError, match=named.replace('.', r'\.')):
        sweep.check(spec)


@pytest.mark.parametrize('args, named', [
    (['--trials', '-1'], '-1'), (['--levels', '1.5'], '1.5'), (['--shares', 'x'], 'x'),
])
def test_the_sweep_command_refuses_bad_settings_with_exit_2(
        tmp_path, capsys, tiny_config, args, named):
    assert cli.main(['sweep', '--config', str(tiny_config), '--out', str(tmp_path / 's'),
                     '--no-progress', *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and named in err[0]


def test_a_sweep_file_with_an_unknown_key_is_refused(tmp_path, capsys, tiny_config):
    bad = tmp_path / 'sweep.yaml'
    bad.write_text('shares: [0, 1]\nnoise_colour: pink\n')
    assert cli.main(['sweep', '--config', str(tiny_config), '--sweep', str(bad),
                     '--out', str(tmp_path / 's'), '--no-progress']) == 2
    assert 'noise_colour' in capsys.readouterr().err


def test_the_sweep_writes_its_tables_and_resumes_without_recomputing(tmp_path, tiny_config):
    assert sweep_cli(tmp_path, tiny_config) == 0
    out = tmp_path / 'sweep'
    analysis = json.loads((out / 'sweep.json').read_text())
    assert [p['point'] for p in analysis['points']] == [
        'share0-level0.05-front', 'share1-level0.05-front', 'control']
    for p in analysis['points']:
        d = p['differences']['5% step 5']
        assert d['ci_low'] <= d['difference'] <= d['ci_high']
    text = (out / 'sweep.md').read_text()
    assert 'Cross-test' in text and (out / 'sweep_step5.png').stat().st_size > 0
    # steps 1-2 are shared: every point holds the first point's phase-1 results
    first = out / 'points' / 'share0-level0.05-front' / 'units'
    other = out / 'points' / 'control' / 'units'
    unit = '5pct-combination/trial-01/step1.json'
    assert json.loads((first / unit).read_text())['best_genome'] == \
        json.loads((other / unit).read_text())['best_genome']
    # resuming: nothing finished is computed again
    files = sorted(out.glob('points/*/units/*/*/step*.json'))
    stamps = {f: f.stat().st_mtime_ns for f in files}
    # a point interrupted before its final tests: only those are run again
    lost = sorted(other.glob('*/*/step5.json'))
    for f in lost:
        f.unlink()
    assert sweep_cli(tmp_path, tiny_config) == 0
    assert all(f.exists() for f in lost)
    kept = [f for f in files if f not in lost]
    assert all(f.stat().st_mtime_ns == stamps[f] for f in kept)
    again = json.loads((out / 'sweep.json').read_text())
    assert [p['means']['3'] for p in again['points']] == \
        [p['means']['3'] for p in analysis['points']]


def test_the_sweep_with_the_ceiling_arm_says_what_training_recovers(tmp_path, tiny_config):
    with open(tiny_config, 'a') as f:
        f.write('ceiling: {population: 3, generations: 2}\n')
    assert sweep_cli(tmp_path, tiny_config, '--ceiling', '--no-control') == 0
    analysis = json.loads((tmp_path / 'sweep' / 'sweep.json').read_text())
    for p in analysis['points']:
        means, rec = p['means'], p['recovery']
        drop = np.mean(list(means['2'].values())) - np.mean(list(means['3'].values()))
        assert rec['drop']['mean'] == pytest.approx(drop)
        back = np.mean(list(means['7'].values())) - np.mean(list(means['3'].values()))
        assert rec['ceiling']['mean'] == pytest.approx(back)
        assert rec['ceiling']['ci_low'] <= rec['ceiling']['mean'] <= rec['ceiling']['ci_high']
    assert 'ceiling: recovered (7 - 3)' in (tmp_path / 'sweep' / 'sweep.md').read_text()


def test_the_control_is_the_simulator_under_the_combination_model():
    base = settings.load(overrides={'trials': 2})
    control = sweep.point_config(base, sweep.Point(None, None, None))
    assert control.hash != base.hash
    evaluate = sweep.control_reality(control)
    genomes = np.zeros((3, 20))
    a, b = evaluate(genomes, np.arange(3)), evaluate(genomes, np.arange(3))
    assert np.array_equal(a, b) and a.shape == (3,)
