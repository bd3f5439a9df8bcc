"""`khepera-noise graph-evolve`: the three nodes in one process, from a parameter file."""
import json
from pathlib import Path

from khepera_noise_ros.testing.domains import next_domain_id
from khepera_noise_ros import cli
from khepera_noise_ros.core import evolution
from khepera_noise_ros.core.evaluation import CoreEvaluator
from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.core.task import Task

CONFIG = Path(__file__).resolve().parents[2] / 'config'


def test_graph_evolve_from_a_parameter_file_equals_the_core(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv('ROS_DOMAIN_ID', str(next_domain_id()))
    results = tmp_path / 'graph.json'
    status = cli.main(['graph-evolve', '--params-file', str(CONFIG / 'sim_ind10.yaml'),
                       '--population', '4', '--generations', '2', '--trials', '2',
                       '--seed', '9', '--steps', '15', '--results', str(results),
                       '--log-level', 'warn'])
    assert status == 0, capsys.readouterr().err
    assert 'best fitness' in capsys.readouterr().out
    record = json.loads(results.read_text())
    assert record['robot']['parameters']['noise_model'] == 'independent'
    assert record['robot']['parameters']['independent_level'] == 0.10

    eas = [evolution.SteadyStateEA(evolution.EAConfig(population=4, generations=2), seed)
           for seed in (9, 10)]
    evolution.evolve(eas, CoreEvaluator(noise=NoiseModel.independent_only(0.10),
                                        task=Task(steps=15)))
    for trial, ea in zip(record['trials'], eas):
        assert trial['best_genome'] == ea.best_genome.tolist()
        assert trial['best_fitness'] == ea.best_fitness
        assert trial['history'] == [vars(g) for g in ea.history]


def test_graph_evolve_reports_a_missing_parameter_file(tmp_path, capsys):
    assert cli.main(['graph-evolve', '--params-file', str(tmp_path / 'none.yaml')]) == 2
    assert 'none.yaml not found' in capsys.readouterr().err
