"""The diagnosis's fast paths give the numbers of the general code beside them: the
dropout repair's sorting network (finite readings), its short-row medians, and the
bootstrap's stratum sums."""
import numpy as np
import pytest

from khepera_noise_ros.gap import bootstrap, dropouts


def recording(seed: int) -> tuple[np.ndarray, dropouts.Runs]:
    """Readings on a coarse lattice with held values, spikes to both extremes and
    runs of several lengths: many readings sit at a channel's extreme."""
    rng = np.random.default_rng(seed)
    n, c = 600, 4
    x = np.round(rng.normal(300.0, 8.0, (n, c)) / 2.0) * 2.0
    x[rng.random((n, c)) < 0.02] = 0.0
    x[rng.random((n, c)) < 0.02] = 525.0
    x[200:230, 1] = x[200, 1]
    edges = np.sort(rng.choice(np.arange(3, n - 3), 12, replace=False))
    return x, dropouts.Runs(np.split(np.arange(n), edges), n)


@pytest.mark.parametrize('seed', range(8))
def test_the_sorting_network_gives_the_general_local_test(seed):
    x, runs = recording(seed)
    xt = np.ascontiguousarray(x.T)
    ends, _ = dropouts._extremes(xt)
    at, group = [], []
    for g in range(2 * x.shape[1]):
        i = runs.place[np.flatnonzero(xt[g // 2] == ends[g // 2, g % 2])]
        at.append(np.sort(i[i >= 0]))
        group.append(np.full(at[-1].size, g))
    i, g = np.concatenate(at), np.concatenate(group)
    far, lower, d, alone = dropouts._local(xt, i, g, ends, runs)
    far2, lower2, d2, alone2 = dropouts._local_finite(xt, i, g, ends, runs)
    assert alone.any() and far.any()              # the comparison is not empty
    np.testing.assert_array_equal(alone2, alone)
    np.testing.assert_array_equal(far2, far)
    np.testing.assert_array_equal(d2[alone], d[alone])
    np.testing.assert_array_equal(lower2[alone], lower[alone])


@pytest.mark.parametrize('seed', range(4))
def test_a_repair_is_the_same_through_either_local_test(seed, monkeypatch):
    x, runs = recording(seed)
    fast = dropouts.repair(x, runs)
    monkeypatch.setattr(dropouts, '_local_finite', dropouts._local)
    general = dropouts.repair(x, runs)
    assert not np.array_equal(fast[0], x)         # something was repaired
    for a, b in zip(fast, general):
        np.testing.assert_array_equal(a, b)


def test_short_row_medians_are_numpy_s_with_nan_where_a_row_has_one():
    x = np.random.default_rng(1).normal(size=(50, 16))
    x[3, 5] = np.nan
    expected = np.median(x, axis=1)
    np.testing.assert_array_equal(dropouts._median(x), expected)
    assert np.isnan(dropouts._median(x)[3])


@pytest.mark.parametrize('n', [1, 7, 8, 9, 127, 128, 129, 1000, 4099])
def test_the_stratum_sum_is_the_sum_of_the_blocks(n):
    rows = np.random.default_rng(n).normal(size=(n, 5)) * 1e3
    np.testing.assert_allclose(bootstrap._pairwise(rows), rows.sum(axis=0), rtol=1e-12)
