"""The khepera-noise commands over the core: noise figures, evolve, episode, errors."""
import csv
import json

import numpy as np
import pytest

from khepera_noise_ros.cli import main


def _read(path):
    with open(path) as f:
        rows = list(csv.reader(f))
    return rows[0], np.array(rows[1:], dtype=float)


def test_noise_figures_order_the_correlations(tmp_path, capsys):
    assert main(['noise', '--out', str(tmp_path), '--samples', '2000']) == 0
    out = capsys.readouterr().out
    corr = {}
    for name in ('fig1', 'fig6', 'fig7'):
        header, data = _read(tmp_path / f'{name}.csv')
        assert header == ['sample', 's0', 's1'] and data.shape == (2000, 3)
        assert (tmp_path / f'{name}.png').stat().st_size > 10000
        corr[name] = np.corrcoef(data[:, 1], data[:, 2])[0, 1]
        assert name in out
    assert abs(corr['fig1']) < 0.1 and corr['fig6'] < 0.15 and corr['fig7'] > 0.9


def test_noise_custom_base_values(tmp_path):
    assert main(['noise', '--base', '100', '200', '300', '--dependent', '0.1',
                 '--independent', '0', '--out', str(tmp_path)]) == 0
    header, data = _read(tmp_path / 'custom.csv')
    assert header == ['sample', 's0', 's1', 's2']
    assert np.corrcoef(data[:, 1:].T).min() > 0.99


def test_evolve_is_reproducible_and_writes_json(tmp_path):
    args = ['evolve', '--population', '6', '--generations', '3', '--steps', '20',
            '--trials', '2', '--quiet', '--model', 'independent', '--independent', '0.05']
    assert main(args + ['--out', str(tmp_path / 'a.json')]) == 0
    assert main(args + ['--out', str(tmp_path / 'b.json')]) == 0
    a = json.loads((tmp_path / 'a.json').read_text())
    b = json.loads((tmp_path / 'b.json').read_text())
    assert a == b
    assert a['noise']['model'] == 'independent' and len(a['trials']) == 2
    trial = a['trials'][0]
    assert len(trial['best_genome']) == 20 and len(trial['history']) == 4
    assert trial['best_fitness'] == max(h['best'] for h in trial['history'])
    # phase 2 from phase 1's best
    assert main(['evolve', '--population', '4', '--generations', '1', '--steps', '10',
                 '--quiet', '--seed-genome', str(tmp_path / 'a.json'),
                 '--out', str(tmp_path / 'c.json')]) == 0


def test_episode_plots_figure_8(tmp_path, capsys):
    assert main(['episode', '--out', str(tmp_path)]) == 0
    header, data = _read(tmp_path / 'episode.csv')
    assert data.shape == (60, len(header))
    fitness = data[:, -1]
    assert 0.5 < fitness.mean() < 1 and (tmp_path / 'fig8.png').exists()
    assert f'{fitness.mean():.3f}'[:4] in capsys.readouterr().out


@pytest.mark.parametrize('argv, words', [
    (['noise', '--base', '1', '2', '--dependent', '-1'], '-1.0'),
    (['evolve', '--groups', '0,1;1,2', '--quiet'], 'overlap'),
    (['evolve', '--groups', 'a,b', '--quiet'], "'a,b'"),
    (['evolve', '--population', '1', '--quiet'], 'population'),
    (['episode', '--genome', '/nonexistent.json'], 'nonexistent'),
])
def test_bad_input_is_one_clear_line(argv, words, capsys, tmp_path):
    assert main(argv + ['--out', str(tmp_path / 'x')]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0] and 'error' in err[0]


def test_wrong_genome_length_is_named(tmp_path, capsys):
    (tmp_path / 'g.json').write_text(json.dumps([0.1] * 19))
    assert main(['episode', '--genome', str(tmp_path / 'g.json'),
                 '--out', str(tmp_path)]) == 2
    assert '20 genes' in capsys.readouterr().err


def test_evolve_trial_k_is_the_ea_with_seed_plus_k(tmp_path):
    """The same rule as the evolution_manager node, so --seed means the same in both."""
    from khepera_noise_ros.core import evolution
    from khepera_noise_ros.core.evaluation import CoreEvaluator
    from khepera_noise_ros.core.task import Task
    assert main(['evolve', '--population', '5', '--generations', '2', '--steps', '10',
                 '--trials', '2', '--seed', '7', '--quiet',
                 '--out', str(tmp_path / 'e.json')]) == 0
    trials = json.loads((tmp_path / 'e.json').read_text())['trials']
    ea = evolution.SteadyStateEA(evolution.EAConfig(population=5, generations=2), seed=8)
    evolution.evolve([ea], CoreEvaluator(task=Task(steps=10)))
    assert trials[1]['best_genome'] == ea.best_genome.tolist()
