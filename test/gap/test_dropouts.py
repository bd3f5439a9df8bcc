"""Dropouts: isolated readings stuck at a sensor's lowest or highest value, judged by an
exact count test against many simulated copies, and found by the diagnosis alone or
beside other effects.

Recordings are made by the simulator (``testing.protocols``) and edited by hand: each
reading of the chosen sensors, with probability ``rate``, reads ``value``.  Controls:
clean recordings, a real ceiling (a limit), a lattice and a spread law's tails must
not get dropouts.
"""
import numpy as np
import pytest

from khepera_noise_ros.effects import (ActuatorTurnError, CorrelatedNoise,
                                       IntensityDependentNoise, SaturationQuantization,
                                       SensorGainOffset, SensorLatency, TemporalDrift)
from khepera_noise_ros.gap import dropouts, diagnose
from khepera_noise_ros.gap.families import having
from khepera_noise_ros.gap.target import Target
from khepera_noise_ros.testing.protocols import (CONFIG, closed_loop_protocol, dropped,
                                                 recorded, stationary_protocol)

OPTIONS = diagnose.Options(config=CONFIG, replicates=40)
# beside an effect that dominates the discrepancy the dropout's step is judged by the
# paired bootstrap on what is left: the default number of replicates
BESIDE = diagnose.Options(config=CONFIG)
ALL = tuple(range(8))
GAIN = SensorGainOffset((2, 5), (1.12, 0.9), (4.0, -6.0))
COUNTED = having('counted')


def stationary(effects=(), seed=5):
    return recorded(stationary_protocol(samples=60), effects, seed=seed)


def closed(effects=(), seed=6):
    return recorded(closed_loop_protocol(24), effects, seed=seed)


def saturation(result) -> dict:
    return next(e for e in result.effects if e['name'] == 'saturation_quantization')


def chosen(result) -> list:
    return [s['name'] for s in result.compound.steps] if result.compound else []


def dropout_in_set(result) -> bool:
    return any(s['name'] == 'saturation_quantization' and s['parameters']['dropout'] > 0
               for s in (result.compound.steps if result.compound else []))


def _count_copies(target):
    return dropouts.count_copies(sum(len(r) for r in target.recordings), target.copies)


# -- the counts --------------------------------------------------------------------------

def test_a_comparison_counts_the_dropouts_against_many_simulated_copies():
    rec = dropped(stationary(), (3,), 0.005, 0.0)
    target = Target([rec], CONFIG, 0, replicates=40)
    assert _count_copies(target) > target.copies
    c = target.compare()
    rows = {k: i for i, k in enumerate(c.keys) if k.family == 'dropout'}
    one = rows[next(k for k in rows if k.sensors == (3,) and 'lowest' in k.part)]
    assert c.real[one] * len(rec) >= 5 and c.sim[one] == 0.0
    assert c.significant()[one]
    others = [i for k, i in rows.items() if 3 not in k.sensors]
    assert not c.significant()[others].any()


@pytest.mark.parametrize('seed', range(10))
def test_clean_recordings_count_no_dropouts(seed):
    """Ten clean recordings (different seeds): no dropout statistic differs, by the counts."""
    for rec in (stationary(seed=seed), recorded(closed_loop_protocol(12), seed=seed)):
        target = Target([rec], CONFIG, 0, replicates=20)
        c = target.compare()
        rows = [i for i, k in enumerate(c.keys) if k.family in COUNTED]
        assert rows and not c.significant()[rows].any()
        assert np.all(np.abs(c.z[rows]) < 3.0)


@pytest.mark.parametrize('robot', [
    SaturationQuantization(ALL, 0.0, 500.0),         # a real ceiling: a limit
    SaturationQuantization(ALL, step=4.0),           # a value lattice
    IntensityDependentNoise(ALL, 0.04, 2.0),         # a spread law's tails
], ids=['ceiling', 'lattice', 'spread law'])
def test_limits_lattices_and_spread_laws_are_not_dropouts(robot):
    target = Target([stationary((robot,))], CONFIG, 0, replicates=20)
    c = target.compare()
    rows = [i for i, k in enumerate(c.keys) if k.family in COUNTED]
    assert rows and not c.significant()[rows].any()
    assert _count_copies(target) > target.copies          # judged by the counts


# -- the diagnosis ----------------------------------------------------------------------

def test_one_sensor_dropping_two_percent_to_zero_is_the_top_effect_and_only_a_dropout():
    result = diagnose.diagnose([dropped(stationary(), (3,), 0.02, 0.0)], OPTIONS)
    assert result.top_effect == 'saturation_quantization', result.effects[:2]
    top = result.effects[0]
    assert top['sensors'] == [3]
    p = top['parameters']
    assert p['dropout'] == pytest.approx(0.02, abs=0.006)
    assert p['dropout_value'] == 0.0
    assert (p['low'], p['high'], p['step']) == (0.0, 525.0, 1.0)     # no limit, no grid
    assert top['heldout_reduction'] > diagnose.MIN_REDUCTION
    assert not [w for w in result.where if w['statistic'] == 'spread' and w['significant']]


def test_one_sensor_dropping_out_half_a_percent_is_found():
    """About a dozen dropouts in 2,400 readings: before the count test, the gap was not
    significant."""
    result = diagnose.diagnose([dropped(stationary(), (3,), 0.005, 0.0)], OPTIONS)
    assert result.gap_significant
    assert result.where[0]['statistic'] == 'dropout' and 3 in result.where[0]['sensors']
    assert result.top_effect == 'saturation_quantization'
    assert saturation(result)['sensors'] == [3]
    assert saturation(result)['parameters']['dropout_value'] == 0.0
    assert dropout_in_set(result)


def test_many_sensors_at_a_small_rate_are_found_pooled():
    result = diagnose.diagnose([dropped(stationary(), ALL, 0.002, 0.0)], OPTIONS)
    assert result.top_effect == 'saturation_quantization', result.effects[:2]
    assert saturation(result)['parameters']['dropout'] == pytest.approx(0.002, abs=0.0015)


def test_dropouts_to_the_top_of_the_range_are_found_at_their_rate():
    result = diagnose.diagnose([dropped(stationary(), (1, 4, 6), 0.01, 525.0)], OPTIONS)
    assert result.top_effect == 'saturation_quantization'
    p = saturation(result)['parameters']
    assert p['dropout_value'] == 525.0
    # dropouts in dark runs (readings near 525) cannot be seen, on either side: the rate
    # is scaled by the share the simulator sees (about 40% here, so 0.4% is seen; ~15
    # seen in the fit part, so the rate is known to about 30%)
    assert 0.005 <= p['dropout'] <= 0.015


def test_dropouts_to_the_top_of_the_scale_in_closed_loop_are_found():
    """The robot spends its episodes in the dark (500), where 525 lies within the
    noise's six robust sds: before, none were found."""
    result = diagnose.diagnose([dropped(closed(), (1, 4, 6), 0.02, 525.0)], OPTIONS)
    assert saturation(result)['sensors'] == [1, 4, 6]
    assert saturation(result)['parameters']['dropout_value'] == 525.0
    assert dropout_in_set(result)


@pytest.mark.parametrize('other', [
    SensorGainOffset((2, 5), (1.12, 0.9), (4.0, -6.0)),
    IntensityDependentNoise(ALL, 0.04, 2.0),
    CorrelatedNoise(((1, 2, 3),), 0.02),
    TemporalDrift(ALL, 0.012, 30.0, True),
    SensorLatency((0, 1, 2, 3), 1),
], ids=lambda e: e.name)
def test_dropouts_beside_another_effect_are_both_in_the_chosen_set(other):
    real = dropped(stationary([other]), ALL if other.name != 'sensor_latency' else (1, 4, 6),
                   0.01, 0.0)
    result = diagnose.diagnose([real], BESIDE)
    assert other.name in chosen(result), chosen(result)
    assert dropout_in_set(result), chosen(result)


def test_dropouts_beside_a_gain_are_added_at_forty_replicates():
    result = diagnose.diagnose([dropped(stationary((GAIN,)), (1, 4, 6), 0.01, 0.0)], OPTIONS)
    assert chosen(result)[0] == 'sensor_gain_offset'
    assert dropout_in_set(result)
    assert saturation(result)['sensors'] == [1, 4, 6]


def test_closed_loop_dropouts_beside_a_turn_error_are_both_in_the_chosen_set():
    """The dropouts happen in the loop, as a robot's do: the controller sees them (put in
    after the recording, the simulator's dropouts would move a loop the robot's never did,
    and a model predicting the closed loop worse is not kept)."""
    real = closed([ActuatorTurnError(0.7, 0.1),
                   SaturationQuantization(ALL, dropout=0.01, dropout_value=0.0)])
    result = diagnose.diagnose([real], BESIDE)
    assert 'actuator_turn_error' in chosen(result)
    assert dropout_in_set(result), chosen(result)
    assert any(w['statistic'] == 'closed_loop_dropout' and w['significant']
               for w in result.where)


def test_dropouts_the_controller_never_saw_are_not_kept_since_they_predict_the_loop_worse():
    """Dropouts put into a closed-loop recording afterwards (a logging fault: the controller
    never saw them): the simulator's dropouts would move the loop the robot's never did, so
    the converter's model predicts the held-out closed loop worse and is not kept."""
    real = dropped(closed([ActuatorTurnError(0.7, 0.1)]), ALL, 0.01, 0.0)
    result = diagnose.diagnose([real], BESIDE)
    assert 'actuator_turn_error' in chosen(result)
    assert not dropout_in_set(result), chosen(result)
    vetoed = [e for e in result.effects + (result.compound.rejected if result.compound else [])
              if e.get('closed_loop_worse')]
    assert 'saturation_quantization' in [e['name'] for e in vetoed], result.compound.rejected


def test_dropouts_in_both_protocols_are_named_not_taken_for_a_turn_error():
    real = [dropped(stationary(), (1, 4, 6), 0.01, 0.0),
            dropped(closed(), (1, 4, 6), 0.01, 0.0, seed=12)]
    result = diagnose.diagnose(real, OPTIONS)
    assert result.top_effect == 'saturation_quantization', result.effects[:2]
    assert chosen(result) == ['saturation_quantization']


@pytest.mark.parametrize('make', [
    lambda: [stationary()], lambda: [closed()],
    lambda: [stationary([SaturationQuantization(ALL, 0.0, 500.0)])],
    lambda: [stationary([SensorGainOffset((2, 5), (1.12, 0.9), (4.0, -6.0))])],
    lambda: [stationary([SensorLatency((0, 1, 2, 3), 1)])],
], ids=['clean', 'clean closed loop', 'ceiling at 500', 'gain and offset', 'latency'])
def test_recordings_without_dropouts_get_none(make):
    result = diagnose.diagnose(make(), OPTIONS)
    assert saturation(result)['parameters'].get('dropout', 0.0) == 0.0
    assert not dropout_in_set(result)
    assert not [w for w in result.where if 'dropout' in w['statistic'] and w['significant']]
