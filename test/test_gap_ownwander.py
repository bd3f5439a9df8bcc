"""A drift of each sensor's own gain beside a much larger flicker all sensors share.

The flicker is white and shared; the drift is slow and each sensor's own.  In the raw
residuals the flicker swamps the drift's autocorrelation; with the part each sensor
shares with the others taken out (``gap.ownwander``) the drift shows, and the drift's
fitter finds it on the sensors that have it, given the flicker.
"""
import pytest

from khepera_noise_ros.gap import effects as fx
from khepera_noise_ros.gap import fit, ownwander, replay
from khepera_noise_ros.gap.target import Target
from test_gap_support import CONFIG, recorded, stationary_protocol

FLICKER = fx.IntensityDependentNoise(tuple(range(8)), 0.06, 2.0, 525.0, 0.0, 'dark', True)
DRIFTING = (0, 2, 3, 5, 6)
DRIFT = fx.TemporalDrift(DRIFTING, 0.01, 40.0, False)


@pytest.fixture(scope='module')
def protocol():
    return stationary_protocol(samples=120)


def _wandering(rec, given, seed=7):
    return ownwander.wandering([rec], [replay.replay(rec, CONFIG, given, seed=seed,
                                                     replicates=2)])


def test_each_sensors_own_drift_shows_beside_a_shared_flicker(protocol):
    rec = recorded(protocol, [DRIFT, FLICKER], seed=11)
    found = _wandering(rec, [FLICKER])
    assert set(found) == set(DRIFTING), {s: round(v['z'], 1) for s, v in found.items()}
    for v in found.values():
        assert 0.3 * DRIFT.sd < v['sd'] < 2.0 * DRIFT.sd, v


def test_a_shared_flicker_alone_is_no_wander(protocol):
    for seed in (11, 12):
        rec = recorded(protocol, [FLICKER], seed=seed)
        assert _wandering(rec, []) == {}          # not even without the flicker simulated
        assert _wandering(rec, [FLICKER]) == {}


def test_the_drift_fitter_finds_each_sensors_wander_given_the_flicker(protocol):
    rec = recorded(protocol, [DRIFT, FLICKER], seed=11)
    target = Target([rec], CONFIG, 3, 'auto', replicates=40).with_given([FLICKER])
    cand = fit.drift(target, target.compare(replicates=40))
    assert cand.effect is not None, cand.note
    assert set(cand.effect.sensors) >= set(DRIFTING), cand.note
    assert not cand.effect.shared
    assert 0.5 * DRIFT.sd < cand.effect.sd < 2.0 * DRIFT.sd, cand.effect


def test_steady_sensors_beside_strongly_drifting_ones_are_not_called_wandering(protocol):
    """The mean of the other sensors carries their wanders into a steady sensor's own
    part; the shared part is then taken from the steady sensors alone."""
    strong = fx.TemporalDrift((0, 1, 2, 3), 0.04, 40.0, False)
    rec = recorded(protocol, [strong, FLICKER], seed=13)
    found = _wandering(rec, [FLICKER])
    assert set(found) == {0, 1, 2, 3}, {s: round(v['z'], 1) for s, v in found.items()}
