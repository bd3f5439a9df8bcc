"""The stationary statistics (``gap.stationary``): the residuals' autocorrelation and the
block length follow the data, and each sensor's own part (what it does not share with
the others) carries a wander that a far larger shared flicker hides from the plain
autocorrelation."""
import numpy as np
import pytest

from khepera_noise_ros.effects import CorrelatedNoise, IntensityDependentNoise, TemporalDrift
from khepera_noise_ros.effects.base import Key
from khepera_noise_ros.gap import evidence, stationary
from khepera_noise_ros.gap.protocol import runs
from khepera_noise_ros.gap.target import Target
from khepera_noise_ros.testing.protocols import CONFIG, recorded, stationary_protocol

FLICKER = IntensityDependentNoise(tuple(range(8)), 0.06, 2.0, 525.0, 0.0, 'dark', True)
DRIFTING = (0, 2, 3, 5, 6)
DRIFT = TemporalDrift(DRIFTING, 0.005, 40.0, False)     # half test_evidence's


def _estimates(rec, family, lag=1) -> dict:
    s = Target([rec], CONFIG, 0, replicates=0).real
    out = {}
    for k, v in zip(s.keys, s.estimate):
        if k.family == family and k.part == f'lag {lag}':
            out.setdefault(k.sensors[0], []).append(v)
    return {sensor: float(np.mean(v)) for sensor, v in out.items()}


def test_autocorrelation_and_block_length_follow_the_data():
    rng = np.random.default_rng(0)
    protocol = stationary_protocol(samples=60, repeats=1)
    rec = recorded(protocol)
    x = np.zeros(len(rec))
    for t in range(1, len(rec)):                 # AR(1) with coefficient 0.8 on sensor 0
        x[t] = 0.8 * x[t - 1] + rng.normal(0, 5)
    rec.readings[:, 0] = 300 + np.round(x)
    s = Target([rec], CONFIG, 0, replicates=100).real
    acf = [v for k, v in zip(s.keys, s.estimate) if k.family == 'autocorrelation'
           and k.sensors == (0,) and k.part == 'lag 1']
    assert np.mean(acf) == pytest.approx(0.8, abs=0.1)
    assert stationary.block_length(rec, [0]) > stationary.block_length(recorded(protocol), [0])


def test_the_own_part_is_what_a_sensor_does_not_share():
    """Each sensor's own AR(1) wander (coefficient 0.8) under white noise all sensors share,
    6-100 times its variance: the plain autocorrelation sees the white noise, the own
    part's sees the wander (less the little the others' mean leaks into it)."""
    rng = np.random.default_rng(1)
    rec = recorded(stationary_protocol(samples=60, repeats=2))
    n, c = rec.readings.shape
    own = np.zeros((n, c))
    for t in range(1, n):
        own[t] = 0.8 * own[t - 1] + rng.standard_normal(c)
    shared = 10.0 * rng.standard_normal((n, 1)) * np.linspace(0.5, 2.0, c)
    rec.readings = 300.0 + shared + own
    plain, mine = _estimates(rec, 'autocorrelation'), _estimates(rec, 'own_autocorrelation')
    for k in range(c):
        assert abs(plain[k]) < 0.2, plain
        assert mine[k] == pytest.approx(0.8, abs=0.15), mine
    assert min(_estimates(rec, 'own_autocorrelation', lag=3).values()) > 0.3


def test_two_sensors_have_no_own_part_statistics():
    rec = recorded(stationary_protocol(samples=20))
    for used, expected in (([0, 1], 0), ([0, 1, 2], 3 * len(stationary.LAGS))):
        rec.manifest = dict(rec.manifest, channels_used=used)
        keys = Target([rec], CONFIG, 0, replicates=0).real.keys
        for condition in rec.conditions():
            assert sum(k.family == 'own_autocorrelation' and k.condition == condition
                       for k in keys) == expected


@pytest.fixture(scope='module')
def target():
    rec = recorded(stationary_protocol(samples=120), [DRIFT, FLICKER], seed=11)
    return Target([rec], CONFIG, 3, 'auto', replicates=60)


def _z(c, family):
    return {s: max(abs(z) for k, z in zip(c.keys, c.z)
                   if k.family == family and k.sensors == (s,)) for s in range(8)}


def test_a_wander_under_a_shared_flicker_shows_in_the_own_part_only(target):
    c = target.compare([FLICKER], replicates=60)
    own, plain = _z(c, 'own_autocorrelation'), _z(c, 'autocorrelation')
    assert min(own[s] for s in DRIFTING) > 4.0, own
    assert np.mean([own[s] for s in DRIFTING]) > 2.0 * np.mean([plain[s] for s in DRIFTING]), \
        (own, plain)
    steady = [s for s in range(8) if s not in DRIFTING]
    assert max(own[s] for s in steady) < min(own[s] for s in DRIFTING), own


def test_simulating_the_wander_takes_its_own_part_discrepancy_away(target):
    def own_part(effects):
        c = target.compare(effects, replicates=60)
        return c.select([k.family == 'own_autocorrelation' for k in c.keys]).discrepancy
    without, with_drift = own_part([FLICKER]), own_part([FLICKER, DRIFT])
    assert without > 50.0 and with_drift < 0.2 * without, (without, with_drift)


def test_the_rows_order_does_not_change_the_statistics():
    """A recording in step order and the same rows shuffled give the same statistics."""
    rec = recorded(stationary_protocol(samples=20), [TemporalDrift((2,), 0.03, 5.0)])
    shuffled = rec.select(np.random.default_rng(0).permutation(len(rec)))
    a, b = (Target([r], CONFIG, 0, replicates=0, block_lengths=[5]).real
            for r in (rec, shuffled))
    assert set(a.keys) == set(b.keys) and len(a.keys) == len(b.keys)
    in_b = b.estimate[[b.index[k] for k in a.keys]]       # keys in order of first appearance
    assert np.allclose(a.estimate, in_b, rtol=1e-5, atol=1e-9, equal_nan=True)


def test_the_block_sums_give_the_pooled_within_run_statistics():
    """Correlations and autocorrelations from the block sums (products in single
    precision, the cross products as a triangle) are the pooled within-run ones computed
    sample by sample."""
    rec = recorded(stationary_protocol(samples=20),
                   [CorrelatedNoise(((0, 1, 2),), 0.03), TemporalDrift((0, 2), 0.03, 5.0)])
    s = Target([rec], CONFIG, 0, replicates=0, block_lengths=[5]).real
    got = dict(zip(s.keys, s.estimate))
    for condition in rec.conditions():
        y, lagged, cells = [], {lag: [] for lag in stationary.LAGS}, set()
        for r in runs(rec):
            if rec.condition[r[0]] != condition:
                continue
            cells.add(rec.heading_deg[r[0]])
            x = rec.readings[r].astype(np.float64)
            y.append(x - x.mean(axis=0))
            for lag in stationary.LAGS:
                lagged[lag].append(y[-1][lag:] * y[-1][:-lag])
        y = np.concatenate(y)
        corr = np.corrcoef(y.T)
        var = (y * y).sum(axis=0) / (len(y) - len(cells))     # the cells' degrees of freedom
        for a in range(8):
            for b in range(a + 1, 8):
                assert got[Key('correlation', (a, b), condition, None)] == \
                    pytest.approx(corr[a, b], rel=1e-4, abs=1e-5)
            for lag in stationary.LAGS:
                acf = np.concatenate(lagged[lag])[:, a].mean() / var[a]
                assert got[Key('autocorrelation', (a,), condition, f'lag {lag}')] == \
                    pytest.approx(acf, rel=1e-4, abs=1e-5)


def test_a_sensor_holding_one_value_has_no_correlation_statistics():
    """Readings converted from another unit are not whole: a sensor that holds one such
    value through each run leaves rounding about the run's mean, which is no noise to
    correlate (it made an autocorrelation of 4.5)."""
    rng = np.random.default_rng(1)
    rec = recorded(stationary_protocol(), seed=4)
    for r in runs(rec):                           # a temperature to 0.01 degree, mapped
        rec.readings[r, 3] = 525 * (29 - np.round(rng.uniform(24.5, 28.9), 2)) / (29 - 24.44)
    s = Target([rec], CONFIG, 0, replicates=0).real
    held = {k.family: v for k, v in zip(s.keys, s.estimate)
            if 3 in k.sensors and k.family in ('correlation', 'autocorrelation', 'kurtosis')}
    assert set(held) == {'correlation', 'autocorrelation', 'kurtosis'}
    assert not np.isfinite(list(held.values())).any(), held
    others = [v for k, v in zip(s.keys, s.estimate)
              if 3 not in k.sensors and k.family == 'autocorrelation']
    assert np.isfinite(others).all() and np.all(np.abs(others) <= 1)


def test_runs_shorter_than_the_slow_window_add_nothing_to_the_slow_part():
    """Episodes of a few samples (a log that loses most readings) have no slow part."""
    rec = recorded(stationary_protocol(), seed=4)
    short = [np.arange(i, i + 3) for i in range(0, 30, 3)]
    assert evidence.part_sums([rec], 'slow', [short]) == {}
    assert evidence.part_sums([rec], 'fast', [short]) != {}
