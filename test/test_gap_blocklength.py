"""The one block-length rule (gap.blocklength) against arch's Politis-White estimator, and its
use by both bootstraps."""
import numpy as np
import pytest

from khepera_noise_ros import synchrony
from khepera_noise_ros.gap import allan, blocklength

arch_bootstrap = pytest.importorskip('arch.bootstrap')


@pytest.mark.parametrize('phi', [0.0, 0.5, 0.9, 0.97])
def test_the_rule_agrees_with_arch_optimal_block_length(phi):
    rng = np.random.default_rng(int(phi * 100))
    n = 4000
    e = rng.standard_normal(n)
    x = np.empty(n)
    x[0] = e[0]
    for t in range(1, n):
        x[t] = phi * x[t - 1] + e[t]
    x -= x.mean()
    ours = blocklength.politis_white(blocklength.autocovariance(x[:, None], [slice(0, n)],
                                                                n // 2)[:, 0], n)
    theirs = float(arch_bootstrap.optimal_block_length(x)['circular'].iloc[0])
    assert ours == pytest.approx(theirs, rel=0.15, abs=1.5), (ours, theirs)


def test_synchrony_and_the_gap_statistics_use_the_same_rule():
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.standard_normal((600, 2)), axis=0) * 0.2 + rng.standard_normal((600, 2))
    x -= x.mean(axis=0)
    segments = [slice(0, 300), slice(300, 600)]
    assert synchrony.block_length(x, segments) == blocklength.block_length(x, segments)
    assert blocklength.block_length(x, segments) > blocklength.block_length(
        rng.standard_normal((600, 2)), segments)


def test_overlapping_allan_deviation_matches_allantools():
    allantools = pytest.importorskip('allantools')
    rng = np.random.default_rng(0)
    y = np.cumsum(rng.standard_normal(2000)) * 0.02 + rng.standard_normal(2000)
    factors = [1, 2, 4, 8, 16, 64]
    _, theirs, _, _ = allantools.oadev(y, rate=1.0, data_type='freq', taus=factors)
    ours = [allan.oadev(y, m)[0] for m in factors]
    np.testing.assert_allclose(ours, theirs, rtol=1e-9)


def test_allan_slopes_name_white_noise_and_a_random_walk():
    rng = np.random.default_rng(1)
    white, walk = rng.standard_normal(20000), np.cumsum(rng.standard_normal(20000))
    factors = [16, 64, 256, 1024]
    assert allan.term(allan.slope(factors, [allan.oadev(white, m)[0] for m in factors])) \
        == 'white'
    assert allan.term(allan.slope(factors, [allan.oadev(walk, m)[0] for m in factors])) \
        == 'random_walk'
