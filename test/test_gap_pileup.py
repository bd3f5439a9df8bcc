"""Limits that touch few readings: a floor or ceiling found from the pile-up at one value.

The robot is the simulator (normal sensor noise, so the tails are smooth) with a
``saturation_quantization`` limit set where it clips only the darkest or brightest
3% of a sensor's readings; the diagnosis gets the recording and the plain simulator.
"""
import dataclasses

import numpy as np
import pytest

from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.gap import diagnose, pileup
from khepera_noise_ros.gap import effects as fx
from test_gap_support import CONDITIONS, CONFIG, recorded, stationary_protocol

NORMAL = dataclasses.replace(
    CONFIG, noise=NoiseModel.independent_only(0.02, distribution='normal'))
DIM = {k: v for k, v in CONDITIONS.items() if k != 'task'}   # no lamp-saturated readings
PROTOCOL = stationary_protocol(samples=150, conditions=DIM)     # 3,600 samples
OPTIONS = diagnose.Options(config=NORMAL, replicates=40)


def _clean():
    return recorded(PROTOCOL, (), config=NORMAL, seed=5)


def _limit(x: np.ndarray, share: float, end: str) -> float:
    """The reading with ``share`` of ``x`` beyond it, at the dark or the bright end."""
    v = np.sort(x)
    return float(v[int(np.ceil((1 - share) * v.size))] if end == 'high'
                 else v[int(share * v.size)])


def _saturation(result) -> dict:
    return next(e for e in result.effects if e['name'] == 'saturation_quantization')


@pytest.mark.parametrize('sensors', [(2,), (1, 4, 6)], ids=['one sensor', 'three sensors'])
def test_a_ceiling_at_the_darkest_three_percent_is_found_with_its_value(sensors):
    x = _clean().readings
    high = _limit(x[:, sensors[0]], 0.03, 'high')
    assert 0.015 < np.mean(x[:, list(sensors)] > high) < 0.04      # a few percent only
    real = recorded(PROTOCOL, [fx.SaturationQuantization(sensors, 0.0, high)], config=NORMAL,
                    seed=5)
    result = diagnose.diagnose([real], OPTIONS)
    assert result.gap_significant
    assert result.where[0]['statistic'] == 'pileup'
    assert result.top_effect == 'saturation_quantization', result.effects[:2]
    top = result.effects[0]
    assert top['sensors'] == list(sensors)
    assert top['parameters']['high'] == high
    assert top['parameters']['low'] == 0.0
    assert top['heldout_reduction'] > diagnose.MIN_REDUCTION


def test_a_floor_at_the_brightest_three_percent_is_found_with_its_value():
    x = _clean().readings[:, 2]
    low = _limit(x, 0.03, 'low')
    assert 0.01 < np.mean(x < low) < 0.04
    real = recorded(PROTOCOL, [fx.SaturationQuantization((2,), low, 525.0)], config=NORMAL,
                    seed=5)
    result = diagnose.diagnose([real], OPTIONS)
    assert result.top_effect == 'saturation_quantization', result.effects[:2]
    top = result.effects[0]
    assert top['sensors'] == [2]
    assert top['parameters']['low'] == low
    assert top['parameters']['high'] == 525.0
    assert top['heldout_reduction'] > diagnose.MIN_REDUCTION


def test_a_clean_recording_gives_no_limit():
    result = diagnose.diagnose([_clean()], OPTIONS)
    assert result.top_effect == 'none'
    assert _saturation(result)['sensors'] == []
    assert not [w for w in result.where if w['statistic'] == 'pileup' and w['significant']]


def test_the_detector_on_hand_made_readings():
    """A clip at the top 3% of normal readings is found (pooled over the sensors sharing
    it); narrower noise, a value lattice and a limit of the reading range are not."""
    rng = np.random.default_rng(3)
    sim = np.round(400 + 10 * rng.standard_normal((6000, 4)))
    real = np.round(400 + 10 * rng.standard_normal((2000, 4)))
    ceiling = float(np.quantile(real[:, 0], 0.97).round())
    clipped = real.copy()
    clipped[:, :2] = np.minimum(clipped[:, :2], ceiling)
    clipped[:, 2] = np.round(400 + 6 * rng.standard_normal(2000))          # narrower
    clipped[:, 3] = np.round(real[:, 3] / 4) * 4                           # a lattice
    found = pileup.limits(clipped, sim, range(4), (0.0, 525.0))
    assert [(f['end'], f['value'], f['sensors']) for f in found] == [(1, ceiling, (0, 1))]
    assert 0.02 < found[0]['share'] < 0.06
    assert pileup.limits(clipped, sim, range(4), (0.0, ceiling)) == []     # the range's own
    assert pileup.limits(real, sim, range(4), (0.0, 525.0)) == []
