"""Dropouts: isolated readings stuck at a sensor's lowest or highest value.

The detector on hand-made readings, then the diagnosis of recordings made by the
simulator (``test_gap_support``) in which readings were replaced by hand: each reading
of the chosen sensors, with probability ``rate``, reads ``value``.  Controls: clean
recordings and a real ceiling (a limit, not a dropout) must not get dropouts.
"""
import copy

import numpy as np
import pytest

from khepera_noise_ros.gap import diagnose, dropout, limits, replay, statistics
from khepera_noise_ros.gap import effects as fx
from khepera_noise_ros.gap.target import Target
from test_gap_support import CONFIG, closed_loop_protocol, recorded, stationary_protocol

OPTIONS = diagnose.Options(config=CONFIG, replicates=40)
# beside an effect that dominates the discrepancy the dropout's step is judged by the
# paired bootstrap on what is left: the default number of replicates
BESIDE = diagnose.Options(config=CONFIG)
ALL = tuple(range(8))


def drop(rec, sensors, rate: float, value: float, seed: int = 11):
    """``rec`` with each reading of ``sensors`` replaced by ``value`` at ``rate``."""
    out = copy.deepcopy(rec)
    rng = np.random.default_rng(seed)
    for s in sensors:
        out.readings[rng.random(len(out)) < rate, s] = value
    return out


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


# -- the detector -----------------------------------------------------------------------

def _runs(n, length):
    return np.split(np.arange(n), np.arange(length, n, length))


def test_isolated_extremes_are_marked_and_repaired_and_nothing_else():
    rng = np.random.default_rng(3)
    clean = np.round(400 + 8 * rng.standard_normal((6000, 3)))
    x = clean.copy()
    lost = rng.random(6000) < 0.02
    x[lost, 0] = 0.0                                     # to zero
    x[lost, 1] = 1023.0                                  # to the top of a 10-bit scale
    x[lost & (np.arange(6000) % 2 == 0), 1] = 0.0        # ... or to zero
    runs = _runs(6000, 300)
    repaired, marks, ends = dropout.repair(x, runs)
    assert marks[:, 0, 0].sum() >= 0.95 * lost.sum()     # pairs next to each other too
    assert np.array_equal(marks[:, 0, 0] > 0, lost & (marks[:, 0, 0] > 0))
    assert marks[:, 1, :].sum() >= 0.95 * lost.sum()
    assert marks[:, 1, 1].sum() > 0 and marks[:, 1, 0].sum() > 0
    assert ends[1].tolist() == [0.0, 1023.0]
    assert marks[:, 2].sum() == 0                        # clean: nothing
    assert dropout.hits(clean, runs).sum() == 0
    # repaired readings lie at the level of their neighbours, not at the extreme
    hit = marks[:, 0, 0] > 0
    assert np.all(np.abs(repaired[hit, 0] - 400) < 60)


def test_a_ceiling_and_a_sweeping_light_are_not_dropouts():
    rng = np.random.default_rng(4)
    noise = np.round(400 + 8 * rng.standard_normal((6000, 3)))
    ceiling = np.minimum(noise, 405.0)                    # a limit: a pile, not isolated
    t = np.arange(6000) % 300
    sweep = np.round(np.clip(500 - 500 * np.exp(-0.5 * ((t - 150) / 3.0) ** 2)
                             + 3 * rng.standard_normal(6000), 50, 525))   # a lamp passes
    x = np.stack([ceiling[:, 0], sweep, noise[:, 2]], axis=1)
    assert (x[:, 1] == 50).sum() > 20
    for moving in (False, True):
        assert dropout.hits(x, _runs(6000, 300), moving).sum() == 0


def test_a_limit_the_light_reaches_is_a_dropout_value_only_where_the_light_is_steady():
    """A lamp holds the sensor at its saturation (50) for whole runs; elsewhere single
    readings read 50.  While the light moves (closed loop) a quick turn can point the
    sensor at the lamp for one step: not a dropout.  In a stationary run the light is
    steady: a lone 50 in a run at 150 is one."""
    rng = np.random.default_rng(5)
    visit = np.round(150 + 3 * rng.standard_normal(6000))
    visit[:1500] = 50.0
    lone = np.arange(1650, 6000, 300)
    visit[lone] = 50.0
    x = visit[:, None]
    assert dropout.hits(x, _runs(6000, 300), moving=True).sum() == 0
    marks = dropout.hits(x, _runs(6000, 300), moving=False)
    assert np.array_equal(np.flatnonzero(marks[:, 0, 0]), lone)


def test_dropout_statistics_see_the_dropouts_and_the_others_do_not():
    rec = stationary()
    lossy = drop(rec, (3,), 0.02, 0.0)
    blocks = [statistics.stationary_blocks(r, ALL, 8) for r in (rec, lossy)]
    clean_stats, lossy_stats = (statistics.compute(b, 0) for b in blocks)
    index = clean_stats.index()
    key = statistics.Key('dropout', (3,), None, dropout.ENDS[0])
    assert clean_stats.estimate[index[key]] == 0.0
    assert lossy_stats.estimate[lossy_stats.index()[key]] == pytest.approx(0.02, abs=0.008)
    spreads = [k for k in clean_stats.keys if k.family == 'spread' and k.sensors == (3,)]
    a = np.array([clean_stats.estimate[index[k]] for k in spreads])
    b = np.array([lossy_stats.estimate[lossy_stats.index()[k]] for k in spreads])
    assert np.max(np.abs(b - a) / (a + 1)) < 0.2     # without the repair: tens of times
    assert not any(k.family == 'dropout' and lossy_stats.estimate[i] > 0
                   for i, k in enumerate(lossy_stats.keys) if k.sensors == (5,))


def test_the_fit_counts_dropouts_in_closed_loop_recordings_against_the_simulator():
    real = drop(closed(), ALL, 0.01, 0.0)
    target = Target([real], CONFIG, seed=1, replicates=0)
    lost = limits.dropouts(target.recordings, target.simulate())
    assert len(lost) >= 4
    assert {v for v, _ in lost.values()} == {0.0}
    clean = Target([closed()], CONFIG, seed=1, replicates=0)
    assert limits.dropouts(clean.recordings, clean.simulate()) == {}


# -- the diagnosis ----------------------------------------------------------------------

def test_one_sensor_dropping_two_percent_to_zero_is_the_top_effect_and_only_a_dropout():
    result = diagnose.diagnose([drop(stationary(), (3,), 0.02, 0.0)], OPTIONS)
    assert result.top_effect == 'saturation_quantization', result.effects[:2]
    top = result.effects[0]
    assert top['sensors'] == [3]
    p = top['parameters']
    assert p['dropout'] == pytest.approx(0.02, abs=0.006)
    assert p['dropout_value'] == 0.0
    assert (p['low'], p['high'], p['step']) == (0.0, 525.0, 1.0)     # no limit, no grid
    assert top['heldout_reduction'] > diagnose.MIN_REDUCTION
    assert not [w for w in result.where if w['statistic'] == 'spread' and w['significant']]


def test_many_sensors_at_a_small_rate_are_found_pooled():
    result = diagnose.diagnose([drop(stationary(), ALL, 0.002, 0.0)], OPTIONS)
    assert result.top_effect == 'saturation_quantization', result.effects[:2]
    assert saturation(result)['parameters']['dropout'] == pytest.approx(0.002, abs=0.0015)


def test_dropouts_to_the_top_of_the_range_are_found_at_their_rate():
    result = diagnose.diagnose([drop(stationary(), (1, 4, 6), 0.01, 525.0)], OPTIONS)
    assert result.top_effect == 'saturation_quantization'
    p = saturation(result)['parameters']
    assert p['dropout_value'] == 525.0
    # dropouts in dark runs (readings near 525) cannot be seen, on either side: the rate
    # is scaled by the share the simulator sees (about 40% here, so 0.4% is seen; ~15
    # seen in the fit part, so the rate is known to about 30%)
    assert 0.005 <= p['dropout'] <= 0.015


@pytest.mark.parametrize('other', [
    fx.SensorGainOffset((2, 5), (1.12, 0.9), (4.0, -6.0)),
    fx.IntensityDependentNoise(ALL, 0.04, 2.0),
    fx.CorrelatedNoise(((1, 2, 3),), 0.02),
    fx.TemporalDrift(ALL, 0.012, 30.0, True),
    fx.SensorLatency((0, 1, 2, 3), 1),
], ids=lambda e: e.name)
def test_dropouts_beside_another_effect_are_both_in_the_chosen_set(other):
    real = drop(stationary([other]), ALL if other.name != 'sensor_latency' else (1, 4, 6),
                0.01, 0.0)
    result = diagnose.diagnose([real], BESIDE)
    assert other.name in chosen(result), chosen(result)
    assert dropout_in_set(result), chosen(result)


def test_closed_loop_dropouts_beside_a_turn_error_are_both_in_the_chosen_set():
    real = drop(closed([fx.ActuatorTurnError(0.7, 0.1)]), ALL, 0.01, 0.0)
    result = diagnose.diagnose([real], BESIDE)
    assert 'actuator_turn_error' in chosen(result)
    assert dropout_in_set(result), chosen(result)
    assert any(w['statistic'] == 'closed_loop_dropout' and w['significant']
               for w in result.where)


def test_dropouts_in_both_protocols_are_named_not_taken_for_a_turn_error():
    real = [drop(stationary(), (1, 4, 6), 0.01, 0.0),
            drop(closed(), (1, 4, 6), 0.01, 0.0, seed=12)]
    result = diagnose.diagnose(real, OPTIONS)
    assert result.top_effect == 'saturation_quantization', result.effects[:2]
    assert chosen(result) == ['saturation_quantization']


@pytest.mark.parametrize('make', [
    lambda: [stationary()], lambda: [closed()],
    lambda: [stationary([fx.SaturationQuantization(ALL, 0.0, 500.0)])],
    lambda: [stationary([fx.SensorGainOffset((2, 5), (1.12, 0.9), (4.0, -6.0))])],
    lambda: [stationary([fx.SensorLatency((0, 1, 2, 3), 1)])],
], ids=['clean', 'clean closed loop', 'ceiling at 500', 'gain and offset', 'latency'])
def test_recordings_without_dropouts_get_none(make):
    result = diagnose.diagnose(make(), OPTIONS)
    assert saturation(result)['parameters'].get('dropout', 0.0) == 0.0
    assert not dropout_in_set(result)
    assert not [w for w in result.where if 'dropout' in w['statistic'] and w['significant']]


def test_repaired_recordings_are_remembered_while_they_live():
    real = drop(stationary(), (3,), 0.02, 0.0)
    prepared = dropout.prepared(real)
    assert prepared is not real and dropout.prepared(prepared) is prepared
    marks, ends = dropout.known(prepared.readings)
    assert marks[:, 3, 0].sum() > 0 and ends[3, 0] == 0.0
    assert prepared.readings[:, 3].min() > 0                 # repaired
    assert replay.kind(prepared) == 'stationary'


def test_readings_flanked_by_their_own_value_are_never_dropouts():
    # the shortcut that skips them must agree with the full test on every reading
    rng = np.random.default_rng(4)
    for _ in range(20):
        n = 400
        col = np.clip(np.round(rng.normal(530, 30, n)), 0, 525)
        col[rng.random(n) < 0.03] = 0.0
        sizes = np.array([n // 4] * 4)
        first = np.cumsum(np.r_[0, sizes[:-1]])
        run_of = np.repeat(np.arange(4), sizes)
        for value in (0.0, 525.0):
            i = np.flatnonzero(col == value)
            if i.size == 0:
                continue
            far, _ = dropout._far(col, i, run_of, first, sizes)
            flanked = dropout._flanked(i, run_of)
            assert not far[flanked].any()
            assert flanked.any() or value == 0.0     # clipped stretches at 525 exist
