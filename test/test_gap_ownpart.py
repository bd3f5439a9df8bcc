"""The own-part autocorrelation statistics: a sensor's own wander, counted in the discrepancy.

Each sensor's slow wander beside a far larger white flicker all sensors share hardly
moves the residuals' autocorrelation; with the shared part taken out of each run
(``gap.ownpart``) it does, so leaving the wander out of the simulator raises the
discrepancy, and putting it in takes that away again.
"""
import numpy as np
import pytest

from khepera_noise_ros.gap import effects as fx
from khepera_noise_ros.gap import ownpart, statistics
from khepera_noise_ros.gap.target import Target
from test_gap_support import CONFIG, recorded, stationary_protocol

FLICKER = fx.IntensityDependentNoise(tuple(range(8)), 0.06, 2.0, 525.0, 0.0, 'dark', True)
DRIFTING = (0, 2, 3, 5, 6)
DRIFT = fx.TemporalDrift(DRIFTING, 0.005, 40.0, False)     # half test_gap_ownwander's


def _run_at(sizes):
    sizes = np.asarray(sizes)
    return {'run_at': (np.arange(sizes.sum()), np.r_[0, np.cumsum(sizes)[:-1]], sizes),
            'runs_sorted': True}


def test_the_own_part_is_what_a_sensor_does_not_share():
    rng = np.random.default_rng(1)
    t, c = 400, 6
    shared = 10.0 * rng.standard_normal((t, 1)) * np.linspace(0.5, 2.0, c)
    own = rng.standard_normal((t, c))
    y = shared + own
    y -= y.mean(axis=0)
    e = ownpart.residuals(y, _run_at([t]))
    assert np.all(e[:ownpart.SKIP] == 0)
    kept = slice(ownpart.SKIP, None)
    for k in range(c):       # the shared part (6-100 times the own variance) is gone
        assert abs(np.corrcoef(y[kept, k], own[kept, k])[0, 1]) < 0.25
        assert np.var(e[kept, k]) < 2.0 * np.var(own[kept, k])    # the others leak a little
        assert abs(np.corrcoef(e[kept, k], own[kept, k])[0, 1]) > 0.75
    # each run on its own: a second run's first samples are left out too
    e2 = ownpart.residuals(y, _run_at([200, 200]))
    assert np.all(e2[200:200 + ownpart.SKIP] == 0) and np.any(e2[200 + ownpart.SKIP] != 0)


def test_two_sensors_have_no_own_part_statistics():
    assert not ownpart.residuals(np.ones((10, 2)), _run_at([10])).any()
    strata = (('task', 0.0), ('task', 90.0))
    keys = statistics._stationary_keys(strata, (0, 1), None, False)
    assert not any(k.family == 'own_autocorrelation' for k in keys)
    keys = statistics._stationary_keys(strata, (0, 1, 2), None, False)
    assert sum(k.family == 'own_autocorrelation' for k in keys) == 3 * len(statistics.LAGS)


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
