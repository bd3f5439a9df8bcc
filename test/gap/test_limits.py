"""Limits and lattices found by the diagnosis: a floor or ceiling that touches few readings,
found from the pile-up at one value, and a value lattice in closed-loop recordings.

The robot is the simulator (normal sensor noise, so the tails are smooth) with a
``saturation_quantization`` limit set where it clips only the darkest or brightest 3%
of a sensor's readings; the diagnosis gets the recording and the plain simulator.
"""
import dataclasses

import numpy as np
import pytest

from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.effects import SaturationQuantization, SensorLatency
from khepera_noise_ros.gap import diagnose
from khepera_noise_ros.gap.families import FAMILIES
from khepera_noise_ros.gap.select import fit_one
from khepera_noise_ros.gap.target import Target
from khepera_noise_ros.testing.protocols import (CONDITIONS, CONFIG, closed_loop_protocol,
                                                 recorded, stationary_protocol)

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
    real = recorded(PROTOCOL, [SaturationQuantization(sensors, 0.0, high)], config=NORMAL,
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
    real = recorded(PROTOCOL, [SaturationQuantization((2,), low, 525.0)], config=NORMAL,
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


# -- closed loop alone -------------------------------------------------------------------

def test_limits_in_a_closed_loop_recording_alone_are_judged_on_it():
    """A floor in closed-loop data with no stationary recording: the saturation fit must
    judge its options on the closed-loop statistics (it once indexed an empty list)."""
    floor = SaturationQuantization((2, 3), low=120.0)
    rec = recorded(closed_loop_protocol(12), [floor], seed=4)
    target = Target([rec], CONFIG, 1, replicates=20)
    cand = fit_one('saturation_quantization', target, target.compare())
    assert 'failed' not in cand.note, cand.note


def test_a_lattice_in_a_closed_loop_recording_alone_is_found():
    lattice = SaturationQuantization(tuple(range(8)), step=6.0, origin=2.0)
    rec = recorded(closed_loop_protocol(12), [lattice], seed=4)
    target = Target([rec], CONFIG, 1, replicates=20)
    cand = fit_one('saturation_quantization', target, target.compare())
    assert cand.effect is not None, cand.note
    assert (cand.effect.step, cand.effect.origin) == (6.0, 2.0)


def test_a_lattice_beside_a_latency_is_chosen_in_closed_loop_only():
    """The loop effect takes nearly all of the closed loop's discrepancy; the lattice is
    judged on its own part (``loop_values``) and chosen too."""
    hidden = [SensorLatency(tuple(range(8)), 2), SaturationQuantization(tuple(range(8)),
                                                                        step=4.0)]
    rec = recorded(closed_loop_protocol(24), hidden, seed=15)
    out = diagnose.diagnose([rec], diagnose.Options(config=CONFIG, replicates=60,
                                                    remainder=False)).to_json()
    chosen = {s['name']: s for s in out['compound']['chosen']}
    assert set(chosen) == {'sensor_latency', 'saturation_quantization'}, list(chosen)
    assert chosen['saturation_quantization']['parameters']['step'] == 4.0
    assert FAMILIES['loop_granularity'].part == 'loop_values'
