"""A slow change shared by all sensors that moves in steps is a drift, not a gain/offset.

The robot is the blind benchmark's emulated robot with no effects, recorded with its
stationary protocol (5 conditions x 2 repeats); the room's light then changes in two
steps between episodes (every reading scaled by the same factor from that episode
on).  A gain or offset is constant in time; the shared per-run levels
(``gap.timesig``) say the levels moved together over time.
"""
import sys
from pathlib import Path

import numpy as np
import pytest

from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.gap import diagnose, replay, split, timesig
from khepera_noise_ros.gap import effects as fx
from khepera_noise_ros.simconfig import SimConfig
from khepera_noise_ros.reality import effects as emu

CONFIG = SimConfig(noise=NoiseModel.independent_only(0.02))
OPTIONS = diagnose.Options(config=CONFIG, replicates=100, compound=False, remainder=False)


@pytest.fixture(scope='module')
def clean():
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'benchmark'))
    from blind_gap import record_stationary, robot
    return record_stationary(robot(emu.EffectsConfig.none(0.02), 3))


def _changed(rec, gain):
    """``rec`` with every reading scaled by ``gain`` (per sample), as the robot reads."""
    out = rec.select(np.ones(len(rec), bool))
    out.readings = np.clip(np.round(rec.readings * gain[:, None]), 0, 525)
    return out


def _steps(rec, steps: dict):
    """A shared step change: from episode e on, readings scaled by 1 + ``steps[e]`` more
    (negative: the room brighter, the Khepera reads lower)."""
    return 1.0 + sum(size * (rec.episode >= e) for e, size in steps.items())


def test_a_shared_two_step_change_is_answered_temporal_drift(clean):
    real = _changed(clean, _steps(clean, {1: -0.06, 3: 0.02}))
    result = diagnose.diagnose([real], OPTIONS)
    assert result.top_effect == 'temporal_drift', result.effects[:2]
    top = result.effects[0]
    assert top['sensors'] == list(range(8))
    assert top['parameters']['shared'] is True
    assert 'move together over time' in top['note']
    gain = next(e for e in result.effects if e['name'] == 'sensor_gain_offset')
    assert gain['sensors'] == [], gain['note']


def test_a_true_per_sensor_offset_is_still_a_gain_offset(clean):
    """Offsets on two sensors, constant in time: no shared change over time."""
    offset = fx.SensorGainOffset((2, 5), (1.0, 1.0), (10.0, -10.0))
    real = replay.replay(clean, CONFIG, [offset], seed=4)
    result = diagnose.diagnose([real], OPTIONS)
    assert result.top_effect == 'sensor_gain_offset', result.effects[:2]
    assert result.effects[0]['sensors'] == [2, 5]


@pytest.mark.parametrize('shape', ['steps', 'ramp', 'sine', 'none'])
def test_the_time_signature_of_shared_changes(clean, shape):
    """Steps, a ramp and a slow wave shared by all sensors show as shared factors that
    vary over the runs more than the simulator's; the unchanged robot does not."""
    t = np.arange(len(clean)) / len(clean)
    gain = {'steps': _steps(clean, {2: -0.04, 6: 0.03}), 'ramp': 1.0 + 0.08 * (t - 0.5),
            'sine': 1.0 + 0.03 * np.sin(2 * np.pi * 1.5 * t), 'none': np.ones(len(clean))}
    real = _changed(clean, gain[shape])
    fit = real.select(split.by_episode(real)[0])
    change = timesig.shared_change([fit], [replay.replay(fit, CONFIG, seed=2, replicates=2)],
                                   range(8))
    assert change['significant'] == (shape != 'none'), change['p_value']
    if shape != 'none':
        assert change['sd'] > 0.005
    # with each run divided by its shared factor, no change is left
    fit.readings = timesig.steady(fit, change['runs'][0])
    again = timesig.shared_change([fit], [replay.replay(fit, CONFIG, seed=2, replicates=2)],
                                  range(8))
    assert not again['significant']
