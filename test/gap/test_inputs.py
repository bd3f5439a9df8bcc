"""Bad or unusual input: a clear error naming the problem, or an honest 'cannot tell'."""
import dataclasses

import numpy as np
import pytest

from khepera_noise_ros import effects as fx
from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.effects import CorrelatedNoise
from khepera_noise_ros.effects.simulate import stationary
from khepera_noise_ros import simconfig
from khepera_noise_ros.experiment import noisefit
from khepera_noise_ros.gap import diagnose, split
from khepera_noise_ros.gap.protocol import ProtocolError
from khepera_noise_ros.recording import FORMAT, Recording, RecordingError
from khepera_noise_ros.testing.protocols import (CONFIG, closed_loop_protocol, recorded,
                                                 stationary_protocol)

OPTIONS = diagnose.Options(config=CONFIG, replicates=30)


def test_recordings_with_different_sensor_counts_are_refused():
    eight = recorded(stationary_protocol(samples=10))
    six = dataclasses.replace(eight, readings=eight.readings[:, :6],
                              manifest=dict(eight.manifest, channels=6))
    with pytest.raises(ValueError, match='disagree on their light channels.*8 channels.*6 '
                                         'channels'):
        diagnose.diagnose([eight, six], OPTIONS)


def test_a_recording_without_variation_is_refused():
    flat = recorded(stationary_protocol(samples=10))
    flat.readings[:] = 300.0
    with pytest.raises(ValueError, match='no variation'):
        diagnose.diagnose([flat], OPTIONS)
    with pytest.raises(ValueError, match='no variation'):
        noisefit.fit(flat)


def test_a_wrong_manifest_is_refused_with_the_key():
    rec = recorded(stationary_protocol(samples=10))
    rec.manifest = dict(rec.manifest, format='something-else/9')
    with pytest.raises(RecordingError, match='format'):
        diagnose.diagnose([rec], OPTIONS)
    rec.manifest = {}
    with pytest.raises(RecordingError, match='manifest'):
        diagnose.diagnose([rec], OPTIONS)


def test_a_closed_loop_recording_needs_its_genome():
    rec = recorded(closed_loop_protocol(4))
    rec.manifest = {k: v for k, v in rec.manifest.items() if k != 'genome'}
    with pytest.raises(ProtocolError, match='genome'):
        diagnose.diagnose([rec], OPTIONS)


def test_too_little_data_and_impossible_hold_outs_are_refused():
    rec = recorded(stationary_protocol(samples=10))
    with pytest.raises(ValueError, match='at least 40'):
        diagnose.diagnose([rec.select(np.arange(len(rec)) < 20)], OPTIONS)
    with pytest.raises(ValueError, match="'dusk'.*not in the recordings"):
        diagnose.diagnose([rec], dataclasses.replace(OPTIONS, held_out=('dusk',)))
    with pytest.raises(ValueError, match='leaves nothing to fit on'):
        split.check_conditions([rec], rec.conditions())
    with pytest.raises(ValueError, match=r"unknown effect\(s\) \['drift'\]; the vocabulary is "
                                         r"\[.*'temporal_drift'"):
        diagnose.diagnose([rec], dataclasses.replace(OPTIONS, effects=('drift', 'temporal_drift')))


def test_bad_simulator_parameters_and_effects_are_refused(tmp_path):
    path = tmp_path / 'p.yaml'
    path.write_text('simulator:\n  ros__parameters:\n    dependant_level: 0.1\n')
    with pytest.raises(ValueError, match="'dependant_level'; did you mean 'dependent_level'"):
        simconfig.load(path)
    path.write_text('simulator:\n  ros__parameters:\n'
                    '    effects: "[{\\"name\\": \\"wobble\\"}]"\n')
    with pytest.raises(ValueError, match='wobble'):
        simconfig.load(path)
    with pytest.raises(FileNotFoundError):
        simconfig.load(tmp_path / 'missing.yaml')
    path.write_text('simulator:\n  ros__parameters:\n    mode: realtime\n    robots: 3\n')
    assert simconfig.load(path) == simconfig.SimConfig()    # other node parameters pass
    # the old message said 'steps must be >= 0'; the effects layer now names the kind too
    with pytest.raises(ValueError, match='steps must be an integer >= 0'):
        fx.from_dict({'name': 'sensor_latency', 'sensors': [0], 'steps': -1})


def board(channels: int = 12, used=tuple(range(10)), seed: int = 3) -> Recording:
    """A light-sensor board we never modelled: 12 channels (two unconnected), 10-bit
    readings, unknown headings, and channels 7-9 sharing a supply ripple."""
    levels = np.linspace(200, 900, channels)
    conditions = {'lights_on': {'note': 'overhead fluorescent'}, 'lights_off': {}}
    runs = [(c, e) for e in range(4) for c in conditions]
    base = np.stack([levels * (0.6 if c == 'lights_on' else 1.0) for c, _ in runs], axis=1)
    effects = (CorrelatedNoise(((7, 8, 9),), 0.03),)
    x = stationary(np.repeat(base[None] / 2, 80, axis=0), NoiseModel.independent_only(0.02),
                   effects, seed) * 2                    # the model runs on a 0..525 scale
    x[:, [c for c in range(channels) if c not in used]] = np.nan
    n = 80 * len(runs)
    manifest = {'format': FORMAT, 'source': 'hardware', 'sample_period_s': 0.5,
                'conditions': conditions, 'channels': channels, 'channels_used': list(used),
                'reading_range': [0, 1023]}
    return Recording(np.repeat(np.arange(len(runs)), 80), np.tile(np.arange(80), len(runs)),
                     np.full(n, np.nan), np.repeat([c for c, _ in runs], 80),
                     np.transpose(x, (2, 0, 1)).reshape(n, channels), np.full(n, np.nan),
                     np.full(n, np.nan), manifest)


def test_a_board_we_never_modelled_is_analysed_for_synchrony_and_fitted():
    rec = board()
    rec.check()
    result = diagnose.diagnose([rec], OPTIONS)
    assert result.top_effect == 'correlated_noise'
    assert result.effects[0]['parameters']['groups'] == [[7, 8, 9]]
    assert any('own means' in note and 'not assessed' in note for note in result.notes)
    fitted = noisefit.fit(rec, level_dependence=False)
    assert fitted.groups == [[7, 8, 9]]
    assert fitted.independent == pytest.approx(0.02, abs=0.006)


def test_groups_beyond_the_khepera_are_fitted_but_not_written_as_simulator_params():
    rec = board(channels=12, used=tuple(range(12)))
    rec.readings[:, 10:] = rec.readings[:, 7:9] + 1        # channels 10, 11 follow 7, 8
    fitted = noisefit.fit(rec, level_dependence=False)
    assert any(max(g) >= 8 for g in fitted.groups)
    assert any('not calibrated' in note for note in fitted.notes)
    with pytest.raises(ValueError, match='sensors are 0..7'):
        fitted.noise_model()


def test_a_reference_noisier_than_the_robot_is_said_so():
    """Every effect adds variation: against a reference noisier than the robot none can
    help, and the notes say what to change; a robot noisier than the reference is not."""
    quiet = recorded(stationary_protocol(), seed=3)                         # 2 % noise
    noisy = simconfig.SimConfig(noise=NoiseModel.independent_only(0.06))
    fast = dict(compound=False, remainder=False, rounding=False, replicates=30)
    said = diagnose.diagnose([quiet], diagnose.Options(config=noisy, **fast)).notes
    assert any(n.startswith('the simulator is noisier than the robot') for n in said), said
    loud = recorded(stationary_protocol(), config=noisy, seed=3)
    said = diagnose.diagnose([loud], diagnose.Options(config=CONFIG, **fast)).notes
    assert not any('noisier' in n for n in said), said
