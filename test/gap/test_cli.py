"""The `khepera-noise diagnose` and `fit` commands on CSV recordings."""
import json

import yaml

from khepera_noise_ros import cli
from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.effects import SensorLatency
from khepera_noise_ros import simconfig
from khepera_noise_ros.recording import write_csv
from khepera_noise_ros.testing.protocols import recorded, stationary_protocol

PARAMS = 'simulator:\n  ros__parameters:\n    noise_model: independent\n' \
         '    independent_level: 0.02\n    mode: lockstep\n'


def test_diagnose_writes_the_json_report_figures_and_loadable_params(tmp_path, capsys):
    latency = SensorLatency((2, 3), 1)
    write_csv(recorded(stationary_protocol(samples=20), (latency,)), tmp_path / 'still')
    (tmp_path / 'sim.yaml').write_text(PARAMS)
    out = tmp_path / 'out'
    code = cli.main(['diagnose', str(tmp_path / 'still'), '--params', str(tmp_path / 'sim.yaml'),
                     '--out', str(out), '--replicates', '40'])
    assert code == 0
    assert 'top effect: sensor_latency' in capsys.readouterr().out
    diagnosis = json.loads((out / 'diagnosis.json').read_text())
    assert diagnosis['format'] == 'khepera-noise-diagnosis/1'
    assert set(diagnosis) >= {'where', 'effects', 'top_effect', 'transfer'}
    assert diagnosis['top_effect'] == 'sensor_latency'
    assert diagnosis['effects'][0]['sensors'] == [2, 3]
    assert diagnosis['where'][0]['significance'] >= diagnosis['where'][-1]['significance']
    for figure in ('correlation.png', 'spread.png', 'shrink.png', 'effects.png'):
        assert (out / figure).stat().st_size > 1000
    assert '![shrink](shrink.png)' in (out / 'report.md').read_text()
    fitted = simconfig.load(out / 'fitted_params.yaml')
    assert fitted.effects == (SensorLatency((2, 3), 1),)
    assert fitted.noise.model == 'independent'


def test_fit_writes_params_the_simulator_reads(tmp_path, capsys):
    truth = NoiseModel('combination', 0.05, 0.02, ((0, 1, 2, 3), (4, 5, 6, 7)))
    write_csv(recorded(stationary_protocol(samples=20),
                       config=simconfig.SimConfig(noise=truth)), tmp_path / 'still')
    code = cli.main(['fit', str(tmp_path / 'still'), '--out', str(tmp_path / 'noise.yaml'),
                     '--no-level-dependence'])
    assert code == 0
    assert 'dependence groups: [[0, 1, 2, 3], [4, 5, 6, 7]]' in capsys.readouterr().out
    params = yaml.safe_load((tmp_path / 'noise.yaml').read_text())['/**']['ros__parameters']
    assert params['dependence_groups'] == '0,1,2,3;4,5,6,7'
    assert simconfig.load(tmp_path / 'noise.yaml').noise.groups == truth.groups
    assert json.loads((tmp_path / 'noise.json').read_text())['format'] == 'khepera-noise-fit/1'


def test_a_missing_or_wrong_manifest_is_a_one_line_error(tmp_path, capsys):
    write_csv(recorded(stationary_protocol(samples=10)), tmp_path / 'rec')
    (tmp_path / 'rec.yaml').unlink()
    assert cli.main(['diagnose', str(tmp_path / 'rec'), '--out', str(tmp_path)]) == 2
    assert 'rec.yaml: no such file' in capsys.readouterr().err
    write_csv(recorded(stationary_protocol(samples=10)), tmp_path / 'rec')
    manifest = yaml.safe_load((tmp_path / 'rec.yaml').read_text())
    manifest['format'] = 'my-own/1'
    (tmp_path / 'rec.yaml').write_text(yaml.safe_dump(manifest))
    assert cli.main(['fit', str(tmp_path / 'rec')]) == 2
    assert 'format must be' in capsys.readouterr().err
