"""The paper's noise model: getnoise bounds, the zero case, group sharing, validation."""
import numpy as np
import pytest

from khepera_noise_ros.core import streams
from khepera_noise_ros.core.noise import NoiseModel, check_groups, getnoise


def test_getnoise_matches_the_c_code_and_stays_in_bounds():
    rng = np.random.default_rng(1)
    v = rng.uniform(0, 525, 10000)
    u = rng.uniform(0, 1, 10000)
    n = getnoise(v, 0.1, u)
    # (int) in C truncates toward zero
    expected = np.array([int(2 * 0.1 * a * b - 0.1 * a) for a, b in zip(v, u)])
    assert np.array_equal(n, expected)
    assert (np.abs(n) <= 0.1 * v).all()
    assert np.array_equal(getnoise(100, 0.05, np.array([0.0, 1.0])), [-5, 5])


@pytest.mark.parametrize('model', ['independent', 'combination'])
def test_zero_levels_and_none_model_give_the_base(model):
    base = np.full((8, 50), 300.0, np.float32)
    draws = np.random.default_rng(0).integers(0, 65536, (8, 50), dtype=np.uint16)
    assert np.array_equal(NoiseModel(model, 0.0, 0.0).apply(base, draws, draws), base)
    assert np.array_equal(NoiseModel('none', 0.5, 0.5).apply(base, draws, draws), base)


def test_readings_are_clipped_to_the_khepera_range():
    base = np.array([[0.0], [525.0]] * 4, np.float32)
    hi = np.full((8, 1), 65535, np.uint16)
    lo = np.zeros((8, 1), np.uint16)
    m = NoiseModel('combination', 0.5, 0.5, groups=((0, 1),))
    assert m.apply(base, hi, hi).max() <= 525 and m.apply(base, lo, lo).min() >= 0


def test_group_of_one_equals_independent_noise():
    """Dependent noise over a group of one sensor is just independent noise."""
    rng = np.random.default_rng(3)
    base = np.rint(rng.uniform(60, 500, (8, 20000))).astype(np.float32)
    draws = rng.integers(0, 65536, (8, 20000), dtype=np.uint16)
    other = rng.integers(0, 65536, (8, 20000), dtype=np.uint16)
    singletons = tuple((s,) for s in range(8))
    comb = NoiseModel('combination', 0.05, 0.0, groups=singletons).apply(base, other, draws)
    ind = NoiseModel.independent_only(0.05).apply(base, draws, other)
    assert np.array_equal(comb, ind)
    corr = np.corrcoef(comb - base)[np.triu_indices(8, 1)]
    assert np.abs(corr).max() < 0.05


def test_dependent_noise_is_shared_within_a_group_only():
    m = NoiseModel('combination', 0.08, 0.0, groups=((0, 1, 2), (3, 4)))
    r = m.sample([100, 110, 120, 130, 140, 150, 160, 170], np.random.default_rng(2), 5000)
    dev = r - np.array([100, 110, 120, 130, 140, 150, 160, 170])
    c = np.corrcoef(dev[:, :5].T)
    assert c[0, 1] > 0.95 and c[3, 4] > 0.95
    assert abs(c[0, 3]) < 0.1
    assert (dev[:, 5:] == 0).all()


def test_combination_correlation_follows_the_split():
    """The paper's Figures 6 and 7: 8% + 2% is weakly, 2% + 8% strongly correlated."""
    def corr(d, i):
        m = NoiseModel('combination', d, i, groups=((0, 1),))
        r = m.sample([100, 110], np.random.default_rng(7), 20000)
        return np.corrcoef(r.T)[0, 1]
    low, high = corr(0.02, 0.08), corr(0.08, 0.02)
    assert 0.0 < low < 0.15 and 0.85 < high < 0.99


def test_normal_distribution_has_the_uniform_spread():
    base = [300.0] * 8
    u = NoiseModel.independent_only(0.1).sample(base, np.random.default_rng(1), 40000)
    n = NoiseModel.independent_only(0.1, distribution='normal').sample(
        base, np.random.default_rng(1), 40000)
    assert abs(u.std() - n.std()) / u.std() < 0.05
    assert n.max() - 300 > 30  # tails reach past the uniform's bound of 30


@pytest.mark.parametrize('kwargs, words', [
    ({'model': 'gaussian'}, "'gaussian'"),
    ({'dependent': -0.1}, '-0.1'),
    ({'independent': float('nan')}, 'nan'),
    ({'independent': float('inf')}, 'inf'),
    ({'distribution': 'cauchy'}, "'cauchy'"),
    ({'groups': ((0, 1), (1, 2))}, 'overlap'),
    ({'groups': ((0, 9),)}, '[9]'),
    ({'groups': ((),)}, 'empty'),
])
def test_bad_noise_settings_are_named(kwargs, words):
    with pytest.raises(ValueError, match=None) as err:
        NoiseModel(**kwargs)
    assert words in str(err.value)


def test_groups_are_normalised_to_tuples():
    assert check_groups([[0, 1], [2]]) == ((0, 1), (2,))


def test_robot_streams_do_not_depend_on_the_batch():
    together = streams.RobotStreams([11, 22, 33]).draw(4)
    alone = streams.RobotStreams([22]).draw(4)
    assert np.array_equal(together[:, 1], alone[:, 0])
    assert not np.array_equal(together[:, 0], together[:, 1])


def test_streams_are_uniform_enough():
    d = streams.RobotStreams(np.arange(2000)).draw(0).astype(np.float64) / streams.UNIT
    assert abs(d.mean() - 0.5) < 0.01 and abs(d.var() - 1 / 12) < 0.005
    b = streams.BatchStream(1, 2000).draw(0).astype(np.float64) / streams.UNIT
    assert abs(b.mean() - 0.5) < 0.01


def test_in_place_apply_equals_copying_apply():
    rng = np.random.default_rng(9)
    base = np.rint(rng.uniform(60, 500, (8, 300))).astype(np.float32)
    draws = rng.integers(0, 65536, (8, 300), dtype=np.uint16)
    model = NoiseModel('combination', 0.1, 0.1)
    expected = model.apply(base, draws, draws[::-1])
    aliased = base.copy()
    assert np.array_equal(model.apply(aliased, draws, draws[::-1], out=aliased), expected)
