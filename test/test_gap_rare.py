"""Rare events: few dropouts, judged by an exact count test, and dropouts to a value apart.

Recordings are made by the simulator (``test_gap_support``) and edited by hand: each
reading of the chosen sensors, with probability ``rate``, reads ``value`` (a dropout).
"""
import numpy as np
import pytest

from khepera_noise_ros.gap import diagnose, dropout, rarecount
from khepera_noise_ros.gap import effects as fx
from khepera_noise_ros.gap.target import Target
from test_gap_dropout import OPTIONS, chosen, closed, drop, dropout_in_set, saturation, \
    stationary
from test_gap_support import CONFIG, closed_loop_protocol, recorded

GAIN = fx.SensorGainOffset((2, 5), (1.12, 0.9), (4.0, -6.0))


# -- the count test ---------------------------------------------------------------------

def test_the_count_test_is_exact_for_few_events_and_silent_without_any():
    # seven against none on twenty times the readings: far beyond chance (the bootstrap's
    # error bar of about the root of the count made it z ~ 2.9)
    z, se = rarecount.test(7, 2400, 0, 48000)
    assert z > 5.5
    assert se == pytest.approx((7 / 2400) / z)
    assert rarecount.test(0, 2400, 0, 48000)[0] == 0.0          # none on either side
    assert rarecount.test(0, 2400, 3, 48000)[0] == 0.0          # fewer real: no evidence
    assert abs(rarecount.test(4, 2400, 80, 48000)[0]) < 1.0     # the same rate
    assert rarecount.test(0, 2400, 200, 48000)[0] < -3.5        # too few real
    # under equal rates the test errs at most at its nominal rate (discrete: fewer)
    rng = np.random.default_rng(0)
    z = [rarecount.test(rng.poisson(2.0), 2400, rng.poisson(40.0), 48000)[0]
         for _ in range(2000)]
    assert np.mean(np.abs(z) > 1.96) < 0.05


def test_a_comparison_counts_the_dropouts_against_many_simulated_copies():
    rec = drop(stationary(), (3,), 0.005, 0.0)
    target = Target([rec], CONFIG, 0, replicates=40)
    assert rarecount.copies(target) > target.copies
    c = target.compare()
    rows = {k: i for i, k in enumerate(c.keys) if k.family == 'dropout'}
    one = rows[next(k for k in rows if k.sensors == (3,) and 'lowest' in k.part)]
    assert c.real[one] * len(rec) >= 5 and c.sim[one] == 0.0
    assert c.significant()[one]
    others = [i for k, i in rows.items() if 3 not in k.sensors]
    assert not c.significant()[others].any()


# -- few dropouts found -------------------------------------------------------------------

def test_one_sensor_dropping_out_half_a_percent_is_found():
    """About a dozen dropouts in 2,400 readings: before, the gap was not significant."""
    result = diagnose.diagnose([drop(stationary(), (3,), 0.005, 0.0)], OPTIONS)
    assert result.gap_significant
    assert result.where[0]['statistic'] == 'dropout' and 3 in result.where[0]['sensors']
    assert result.top_effect == 'saturation_quantization'
    assert saturation(result)['sensors'] == [3]
    assert saturation(result)['parameters']['dropout_value'] == 0.0
    assert dropout_in_set(result)


def test_dropouts_beside_a_gain_are_added_at_forty_replicates():
    result = diagnose.diagnose([drop(stationary((GAIN,)), (1, 4, 6), 0.01, 0.0)], OPTIONS)
    assert chosen(result)[0] == 'sensor_gain_offset'
    assert dropout_in_set(result)
    assert saturation(result)['sensors'] == [1, 4, 6]


def test_dropouts_to_a_value_apart_from_every_other_reading_are_marked():
    """A dark sensor (level 500, noise of +-10) whose light also moves: lost readings at
    525 lie within six robust sds of the level and beside neighbours that move, but the
    value stands apart from every reading the sensor gave otherwise.  Readings on a coarse
    lattice, or a clean sensor, get no marks."""
    rng = np.random.default_rng(8)
    n = 6000
    t = np.arange(n)
    light = 500 - 250 * np.clip(np.sin(t / 7.0), 0, None) ** 4        # a lamp passing
    clean = np.round(light[:, None] + rng.uniform(-10, 10, (n, 3)))
    x = clean.copy()
    lost = rng.random(n) < 0.02
    x[lost, 0] = 525.0
    x[:, 2] = np.round(clean[:, 1] / 16) * 16                          # a lattice
    runs = np.split(t, np.arange(60, n, 60))
    marks = dropout.repair(x, runs, moving=True)[1]
    assert marks[:, 0, 1].sum() >= 0.9 * lost.sum()
    assert np.all(lost[marks[:, 0, 1] > 0])
    assert marks[:, 1:].sum() == 0
    assert dropout.repair(clean, runs, moving=True)[1].sum() == 0


def test_dropouts_to_the_top_of_the_scale_in_closed_loop_are_found():
    """The robot spends its episodes in the dark (500), where 525 lies within the
    noise's six robust sds: before, none were found."""
    result = diagnose.diagnose([drop(closed(), (1, 4, 6), 0.02, 525.0)], OPTIONS)
    assert saturation(result)['sensors'] == [1, 4, 6]
    assert saturation(result)['parameters']['dropout_value'] == 525.0
    assert dropout_in_set(result)


# -- controls ---------------------------------------------------------------------------

@pytest.mark.parametrize('seed', range(10))
def test_clean_recordings_count_no_dropouts(seed):
    """Ten clean recordings (different seeds): no dropout statistic differs, by the counts."""
    for rec in (stationary(seed=seed), recorded(closed_loop_protocol(12), seed=seed)):
        target = Target([rec], CONFIG, 0, replicates=20)
        c = target.compare()
        rows = [i for i, k in enumerate(c.keys) if k.family in rarecount.FAMILIES]
        assert rows and not c.significant()[rows].any()
        assert np.all(np.abs(c.z[rows]) < 3.0)


@pytest.mark.parametrize('robot', [
    fx.SaturationQuantization(tuple(range(8)), 0.0, 500.0),      # a real ceiling: a limit
    fx.SaturationQuantization(tuple(range(8)), step=4.0),          # a value lattice
    fx.IntensityDependentNoise(tuple(range(8)), 0.04, 2.0),        # a spread law's tails
], ids=['ceiling', 'lattice', 'spread law'])
def test_limits_lattices_and_spread_laws_are_not_dropouts(robot):
    target = Target([stationary((robot,))], CONFIG, 0, replicates=20)
    c = target.compare()
    rows = [i for i, k in enumerate(c.keys) if k.family in rarecount.FAMILIES]
    assert rows and not c.significant()[rows].any()
    assert rarecount.copies(target) > target.copies          # judged by the counts
