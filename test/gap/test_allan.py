"""Allan deviation of the residuals (``gap.allan``) against allantools, and its slopes."""
import numpy as np
import pytest

from khepera_noise_ros.gap import allan


def test_overlapping_allan_deviation_matches_allantools():
    allantools = pytest.importorskip('allantools')
    rng = np.random.default_rng(0)
    y = np.cumsum(rng.standard_normal(2000)) * 0.02 + rng.standard_normal(2000)
    factors = [1, 2, 4, 8, 16, 64]
    _, theirs, _, _ = allantools.oadev(y, rate=1.0, data_type='freq', taus=factors)
    ours = allan.deviation([y[:, None]], factors, 1)[0][:, 0]
    np.testing.assert_allclose(ours, theirs, rtol=1e-9)


def test_allan_slopes_name_white_noise_and_a_random_walk():
    rng = np.random.default_rng(1)
    white, walk = rng.standard_normal(20000), np.cumsum(rng.standard_normal(20000))
    factors = [16, 64, 256, 1024]

    def named(y):
        return allan.term(allan.slope(factors, allan.deviation([y[:, None]], factors, 1)[0][:, 0]))
    assert named(white) == 'white'
    assert named(walk) == 'random_walk'
