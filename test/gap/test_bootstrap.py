"""The project's block bootstrap (``gap.bootstrap``): the one block-length rule against arch's
Politis-White estimator and its use by both bootstraps, the autocovariance through the
spectrum, and the stratified resampling against a plain computation."""
import numpy as np
import pytest
from scipy import sparse

from khepera_noise_ros import synchrony
from khepera_noise_ros.gap import bootstrap

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
    ours = bootstrap.politis_white(bootstrap.autocovariance(x[:, None], [slice(0, n)],
                                                            n // 2)[:, 0], n)
    theirs = float(arch_bootstrap.optimal_block_length(x)['circular'].iloc[0])
    assert ours == pytest.approx(theirs, rel=0.15, abs=1.5), (ours, theirs)


def test_synchrony_and_the_gap_statistics_use_the_same_rule():
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.standard_normal((600, 2)), axis=0) * 0.2 + rng.standard_normal((600, 2))
    x -= x.mean(axis=0)
    segments = [slice(0, 300), slice(300, 600)]
    assert synchrony.block_length(x, segments) == bootstrap.block_length(x, segments)
    assert bootstrap.block_length(x, segments) > bootstrap.block_length(
        rng.standard_normal((600, 2)), segments)


def test_autocovariance_through_the_spectrum_equals_lag_by_lag_sums():
    rng = np.random.default_rng(2)
    x = rng.normal(size=(700, 4)).cumsum(axis=0) * 0.1 + rng.normal(size=(700, 4))
    segments = [slice(0, 300), slice(300, 301), slice(301, 700)]
    plain = np.zeros((151, 4))
    for s in segments:
        seg = x[s]
        for lag in range(min(150, len(seg) - 1) + 1):
            plain[lag] += (seg[lag:] * seg[:len(seg) - lag]).sum(axis=0)
    plain /= 700
    assert np.allclose(bootstrap.autocovariance(x, segments, 150), plain, rtol=0,
                       atol=1e-12 * np.abs(plain).max())
    assert bootstrap.block_length(x, segments[::2], 1, 100) > 5     # the walk needs long


def _blocks(rng, strata=5, per=(0, 1, 3, 7, 12), width=6, bad=False) -> bootstrap.Blocks:
    """Blocks in shuffled stratum order, one stratum with none."""
    stratum = np.concatenate([np.full(per[s % len(per)], s) for s in range(strata)])
    rng.shuffle(stratum)
    sums = rng.normal(size=(stratum.size, width)) * 10.0 ** rng.integers(-3, 4, width)
    if bad:
        sums[1, 2] = np.nan
    table, layout = bootstrap.pack({'x': sums})
    return bootstrap.Blocks('stationary', (0,), [f's{s}' for s in range(strata)], stratum,
                            table, layout)


def _weights_plain(blocks: bootstrap.Blocks, replicates: int, rng) -> np.ndarray:
    w = np.zeros((1 + replicates, blocks.stratum.size))
    w[0] = 1.0
    for lo, hi in zip(blocks.edges[:-1], blocks.edges[1:]):
        if replicates and hi > lo:
            picks = rng.integers(lo, hi, size=(replicates, hi - lo))
            rows = np.repeat(np.arange(1, replicates + 1), hi - lo)
            np.add.at(w, (rows, picks.ravel()), 1.0)
    return w


def _sums_plain(blocks: bootstrap.Blocks, w: np.ndarray) -> np.ndarray:
    r, b = w.shape
    strata = len(blocks.strata)
    rows = (np.arange(r)[:, None] * strata + blocks.stratum[None, :]).ravel()
    pick = sparse.csr_matrix((w.ravel(), (rows, np.tile(np.arange(b), r))),
                             shape=(r * strata, b))
    return np.asarray(pick @ blocks.sums).reshape(r, strata, -1)


@pytest.mark.parametrize('bad', [False, True])
def test_bootstrap_weights_and_sums_equal_the_plain_ones(bad):
    rng = np.random.default_rng(3)
    blocks = _blocks(rng, bad=bad)
    assert np.all(np.diff(blocks.stratum) >= 0)           # kept in stratum order
    for replicates in (0, 1, 40):
        w = bootstrap.weights(blocks, replicates, np.random.default_rng(11))
        plain = _weights_plain(blocks, replicates, np.random.default_rng(11))
        assert np.array_equal(w, plain)
        assert w[1:].sum() == replicates * blocks.stratum.size
        resampled = bootstrap.resampled(blocks, replicates, 11)
        assert np.allclose(resampled, _sums_plain(blocks, w), rtol=1e-12, atol=0,
                           equal_nan=True)


def test_packed_parts_are_read_back_by_name():
    rng = np.random.default_rng(1)
    parts = {'n': rng.random((40, 1)), 'sx': rng.random((40, 3)),
             'sq': rng.random((40, 3, 3)), 'lag': rng.random((40, 2, 3))}
    table, layout = bootstrap.pack(parts)
    blocks = bootstrap.Blocks('stationary', (0, 1, 2), ['a'], np.zeros(40, np.int64), table,
                              layout)
    for name, value in parts.items():
        assert blocks.has(name)
        assert np.array_equal(blocks.part(blocks.sums, name), value)
    assert not blocks.has('other')
