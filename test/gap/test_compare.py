"""Real against simulated statistics (``gap.compare``): by chance the simulator against itself
differs by about N(0, 1); a real difference is significant and ranked first; Holm's
correction; and the count test that judges rare events (dropouts)."""
import numpy as np
import pytest

from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.effects.fitting import holm
from khepera_noise_ros.gap import compare
from khepera_noise_ros.simconfig import SimConfig
from khepera_noise_ros.gap.target import Target
from khepera_noise_ros.testing.protocols import CONFIG, recorded, stationary_protocol


def _stats(rec, seed):
    """Every statistic of ``rec`` with 100 bootstrap replicates."""
    return Target([rec], CONFIG, seed, replicates=100).real


def test_the_same_simulator_twice_differs_by_chance_only():
    protocol = stationary_protocol()
    c = compare.compare(_stats(recorded(protocol, seed=1), 1),
                        _stats(recorded(protocol, seed=2), 2))
    assert not c.significant().any()
    assert 0.7 < np.std(c.z) < 1.4         # standardised differences are about N(0, 1)


def test_a_real_difference_is_significant_and_ranked_first():
    protocol = stationary_protocol()
    noisier = SimConfig(noise=NoiseModel.independent_only(0.04))
    c = compare.compare(_stats(recorded(protocol, config=noisier, seed=1), 1),
                        _stats(recorded(protocol, seed=2), 2))
    top = compare.entries(c, limit=5)
    assert c.significant().sum() > 20
    assert top[0]['statistic'] == 'spread' and top[0]['real'] > top[0]['sim']


def test_holm_adjusts_and_keeps_order():
    p = np.array([0.01, 0.04, 0.03, 0.5])
    adjusted = holm(p)
    assert adjusted.tolist() == pytest.approx([0.04, 0.09, 0.09, 0.5])


def test_the_count_test_is_exact_for_few_events_and_silent_without_any():
    # seven against none on twenty times the readings: far beyond chance (the bootstrap's
    # error bar of about the root of the count made it z ~ 2.9)
    z, se = compare.test(7, 2400, 0, 48000)
    assert z > 5.5
    assert se == pytest.approx((7 / 2400) / z)
    assert compare.test(0, 2400, 0, 48000)[0] == 0.0          # none on either side
    assert compare.test(0, 2400, 3, 48000)[0] == 0.0          # fewer real: no evidence
    assert abs(compare.test(4, 2400, 80, 48000)[0]) < 1.0     # the same rate
    assert compare.test(0, 2400, 200, 48000)[0] < -3.5        # too few real
    # under equal rates the test errs at most at its nominal rate (discrete: fewer)
    rng = np.random.default_rng(0)
    z = [compare.test(rng.poisson(2.0), 2400, rng.poisson(40.0), 48000)[0]
         for _ in range(2000)]
    assert np.mean(np.abs(z) > 1.96) < 0.05
