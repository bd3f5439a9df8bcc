"""The third set of shortcuts of the diagnosis, held against the plain computations.

Block sums added straight into the stratum-ordered table (``gap.blocksums``), the pile
ends found by value (``gap.blockcounts.pile_ends``) and the effects' random draws
remembered (``gap.draws``): each gives the values of what it replaces, bit for bit.
Speed is ``benchmark/bench_diagnose.py``'s.
"""
import numpy as np
import pytest

from khepera_noise_ros.gap import (blockcounts, blocksums, draws, dropout, pileup, rarecount,
                                   resample, simulate, statistics)
from khepera_noise_ros.gap import effects as fx
from test_gap_support import recorded, stationary_protocol, sums_both_ways


def _cut(rng, n_blocks: int, largest: int):
    sizes = rng.integers(1, largest + 1, n_blocks)
    starts = np.r_[0, np.cumsum(sizes)[:-1]]
    return starts, sizes


@pytest.mark.parametrize('dtype,shape', [(np.float32, (36,)), (np.float64, (8,)),
                                         (np.float32, (8, 2)), (np.int64, (8,)),
                                         (np.float64, (1,))])
def test_segments_add_rows_as_reduceat_does(dtype, shape):
    rng = np.random.default_rng(len(shape) + shape[0])
    starts, sizes = _cut(rng, 400, blocksums.SEQUENTIAL)
    n = int(sizes.sum())
    values = (rng.standard_normal((n,) + shape) * 10.0 ** rng.integers(-3, 4, (n,) + shape))
    values[rng.random(values.shape) < 0.05] = -0.0          # signed zeros stay as numpy has them
    values[rng.random(values.shape) < 0.02] = 0.0
    values = values.astype(dtype) if dtype is not np.int64 else \
        rng.integers(-1 << 40, 1 << 40, (n,) + shape)
    plain = np.add.reduceat(values, starts, axis=0).reshape(starts.size, -1)
    targets = np.arange(starts.size)
    rows = rng.permutation(starts.size)                 # each block to its own row
    cut = blocksums.Segments(starts, targets, n, rows)
    assert cut.largest == sizes.max()
    out = np.zeros((starts.size, plain.shape[1] + 3), dtype if dtype is np.int64 else float)
    cut.add(blocksums.taken(values), out, slice(2, 2 + plain.shape[1]))
    expect = plain.astype(out.dtype)
    assert np.array_equal(out[rows, 2:2 + plain.shape[1]], expect)
    # bit for bit, signed zeros included
    assert np.array_equal(np.signbit(out[rows, 2:2 + plain.shape[1]]), np.signbit(expect))
    assert not out[:, :2].any() and not out[:, 2 + plain.shape[1]:].any()


def test_segments_of_longer_blocks_are_not_added_directly():
    """Blocks of more than ``SEQUENTIAL`` rows: numpy adds them pairwise, so the layout
    keeps the general path (and the general path is what the direct one is held to)."""
    rec = recorded(stationary_protocol(samples=15), [fx.TemporalDrift((0, 2), 0.03, 5.0)])
    statistics.stationary_blocks(rec, rec.channels_used, blocksums.SEQUENTIAL + 1)
    assert not statistics._layout(rec, blocksums.SEQUENTIAL + 1)['direct']
    statistics.stationary_blocks(rec, rec.channels_used, blocksums.SEQUENTIAL)
    assert statistics._layout(rec, blocksums.SEQUENTIAL)['direct']


@pytest.mark.parametrize('effects,length,shuffle', [
    ((fx.SensorLatency((2,), 1),), 5, False),
    ((fx.TemporalDrift((0, 2), 0.03, 5.0), fx.IntensityDependentNoise((1, 3))), 4, False),
    ((fx.SaturationQuantization((0, 1, 2, 3), step=4.0, origin=1.0, dropout=0.02),), 8, False),
    ((fx.CorrelatedNoise(((0, 1), (4, 5)), 0.03),), 5, True),
    ((fx.SensorGainOffset((1, 6), (1.1, 0.9), (5.0, -3.0)),), 2, True)])
def test_block_sums_straight_into_the_table_equal_the_general_path(effects, length, shuffle):
    rec = recorded(stationary_protocol(samples=13), effects)
    if shuffle:         # rows not in block order, singles left out: gathered first
        rec = rec.select(np.random.default_rng(1).permutation(len(rec)))
    direct, general = sums_both_ways(rec, length, 'direct')
    assert direct.layout == general.layout
    assert np.array_equal(direct.sums, general.sums)
    assert np.array_equal(np.signbit(direct.sums), np.signbit(general.sums))
    assert np.array_equal(direct.stratum, general.stratum)
    assert direct.part(direct.sums, 's2').any() and direct.part(direct.sums, 'edge').any()


def test_block_sums_of_readings_not_integer_and_of_gathered_lag_pairs():
    rec = recorded(stationary_protocol(samples=13), [fx.SensorLatency((2,), 1)])
    rec.readings = rec.readings + np.random.default_rng(2).normal(0, 0.3, rec.readings.shape)
    direct, general = sums_both_ways(rec, 5, 'direct')
    assert np.array_equal(direct.sums, general.sums)
    assert not direct.extra['integer']
    lay = statistics._layout(rec, 5)
    kept = lay['lag_shifts']
    lay['lag_shifts'] = [None] * len(kept)          # products of gathered pairs
    try:
        gathered, plain = sums_both_ways(rec, 5, 'direct')
    finally:
        lay['lag_shifts'] = kept
    assert np.array_equal(gathered.sums, plain.sums)
    assert np.array_equal(gathered.sums, direct.sums)


def _integer_columns(rng) -> np.ndarray:
    n, c = int(rng.integers(1, 400)), int(rng.integers(1, 5))
    centre = rng.choice([0.0, 50.0, 500.0, 1023.0])
    x = np.round(rng.normal(centre, rng.choice([0.3, 2.0, 15.0, 200.0]), (n, c)))
    if rng.random() < 0.4:          # a floor or ceiling holding some readings
        x = np.clip(x, np.round(np.quantile(x, rng.random() * 0.2)), None)
    if rng.random() < 0.3:          # a few strays far out
        x[rng.integers(0, n, 3), rng.integers(0, c)] = rng.choice([0.0, 1023.0, 5e5])
    return x


def test_pile_ends_by_value_are_the_edge_hits_of_every_sample():
    rng = np.random.default_rng(7)
    compared = spread_out = 0
    for _ in range(300):
        x = _integer_columns(rng)
        low = int(x.min())
        xi = (x - low).astype(np.int64)
        span = int(xi.max()) + 1
        hist = np.stack([np.bincount(xi[:, k], minlength=span) for k in range(x.shape[1])])
        ends = blockcounts.pile_ends(hist)
        if ends is None:            # a channel over 1e5 values: pileup's own way is kept
            spread_out += 1
            assert any(np.ptp(x[:, k]) >= 1e5 for k in range(x.shape[1]))
            continue
        by_sample = ends[xi, np.arange(x.shape[1])[None, :]]
        assert np.array_equal(by_sample, pileup.edge_hits(x).astype(bool))
        compared += 1
    assert compared > 250 and spread_out > 0


def _plain_draws(entropy, calls) -> list:
    rng = np.random.default_rng(list(entropy))
    return [getattr(rng, method)(size) for method, size in calls]


def test_remembered_draws_are_the_generators_own():
    draws._KEPT.clear()
    entropy = simulate._entropy(11)
    a = [('standard_normal', (50, 2, 1)), ('random', (50, 3)), ('standard_normal', 7)]
    b = [('standard_normal', (50, 2, 1)), ('standard_normal', (50, 1, 1)), ('random', 4)]
    for calls in (a, a, b, a[:2] + b[1:], b):        # repeats, shared prefixes, new branches
        rng = draws.Remembered(entropy)
        got = [getattr(rng, method)(size) for method, size in calls]
        for mine, plain in zip(got, _plain_draws(entropy, calls)):
            assert mine.dtype == plain.dtype and np.array_equal(mine, plain)
            mine *= 0.0                 # a copy: what is remembered stays as it was
    assert len(draws._KEPT) == 7
    # another use of the generator gets the generator itself, at its point in the stream
    rng = draws.Remembered(entropy)
    first = rng.standard_normal((50, 2, 1))
    ints = rng.integers(0, 10, 5)
    after = rng.standard_normal(3)
    plain = np.random.default_rng(list(entropy))
    assert np.array_equal(first, plain.standard_normal((50, 2, 1)))
    assert np.array_equal(ints, plain.integers(0, 10, 5))
    assert np.array_equal(after, plain.standard_normal(3))


def test_remembered_draws_are_bounded_and_survive_forgetting(monkeypatch):
    draws._KEPT.clear()
    draws._SIZE[0] = 0
    monkeypatch.setattr(draws, 'KEPT_BYTES', 3 * 8 * 100)
    entropy = simulate._entropy(3)
    calls = [('standard_normal', 100)] * 5
    for _ in range(2):
        rng = draws.Remembered(entropy)
        got = [rng.standard_normal(100) for _ in calls]
        assert all(np.array_equal(m, p) for m, p in zip(got, _plain_draws(entropy, calls)))
        assert draws._SIZE[0] <= draws.KEPT_BYTES and len(draws._KEPT) == 3


def test_a_replay_with_remembered_draws_equals_one_with_a_fresh_generator(monkeypatch):
    effects = (fx.TemporalDrift((0, 2), 0.03, 5.0, False), fx.IntensityDependentNoise((1, 3)),
               fx.SaturationQuantization((4,), dropout=0.05))
    base = np.full((200, 8, 2), 400.0)
    draws._KEPT.clear()
    first = simulate.stationary(base, simulate.NoiseModel.independent_only(0.02), effects, 5)
    again = simulate.stationary(base, simulate.NoiseModel.independent_only(0.02), effects, 5)
    monkeypatch.setattr(draws, 'Remembered', lambda e: np.random.default_rng(list(e)))
    fresh = simulate.stationary(base, simulate.NoiseModel.independent_only(0.02), effects, 5)
    assert np.array_equal(first, fresh) and np.array_equal(again, fresh)


def test_cross_products_of_gathered_rows_are_the_upper_products():
    y = np.random.default_rng(4).normal(0, 30, (3, 50, 8)).astype(np.float32)
    by_index = blockcounts.upper_of(y)
    assert np.array_equal(by_index.reshape(-1, 36), blockcounts.upper_products(y.reshape(-1, 8)))


def test_rare_counts_summed_in_place_are_the_counts_of_the_chosen_channels(monkeypatch):
    rec = recorded(stationary_protocol(samples=13),
                   [fx.SaturationQuantization((1, 4, 6), dropout=0.03)])
    rec.manifest = dict(rec.manifest, channels_used=[6, 1, 4, 0])
    rec = dropout.prepared(rec)
    marks = dropout.known(rec.readings)[0]
    assert marks[:, [1, 4, 6]].sum() > 10
    fast = rarecount.counts([rec])
    monkeypatch.setattr(rarecount, 'EXACT', 0)          # the plain way: pick, then sum
    plain = rarecount.counts([rec])
    assert fast == plain
    hits = np.count_nonzero(marks[:, [6, 1, 4, 0]], axis=0)
    for k, sensor in enumerate([6, 1, 4, 0]):
        for end, name in enumerate(dropout.ENDS):
            key = statistics.Key('dropout', (sensor,), None, name)
            assert fast[key] == [float(hits[k, end]), float(len(rec))]


@pytest.mark.parametrize('effects', [(fx.SensorLatency((2,), 1),),
                                     (fx.SaturationQuantization((1, 4), dropout=0.02),)])
def test_resampled_sums_of_the_rare_parts_apart_equal_the_whole_product(effects):
    rec = recorded(stationary_protocol(samples=13), effects)
    blocks = statistics.stationary_blocks(rec, rec.channels_used, 5)
    rare = blocks.extra['rare']
    assert blocks.layout['dropped'][0].start == rare          # the rare parts come last
    assert 0 < np.count_nonzero(blocks.sums[:, rare:].any(axis=1)) < len(blocks.stratum) / 2
    whole = statistics.Blocks(blocks.kind, blocks.channels, blocks.strata, blocks.stratum,
                              blocks.sums, blocks.layout, {'integer': True})
    for replicates, seed in ((60, 1), (7, 2)):
        resample._PICKS.clear()
        apart = resample.resampled(blocks, replicates, seed)
        resample._PICKS.clear()
        plain = resample.resampled(whole, replicates, seed)
        assert np.array_equal(apart, plain)
        assert np.array_equal(np.signbit(apart), np.signbit(plain))
    bad = statistics.Blocks(blocks.kind, blocks.channels, blocks.strata, blocks.stratum,
                            blocks.sums.copy(), blocks.layout, dict(blocks.extra))
    bad.sums[0, rare] = np.inf              # not finite: the whole product, undrawn kept
    w = statistics.weights(bad, 40, np.random.default_rng(3))
    resample._PICKS.clear()
    assert np.array_equal(resample.resampled(bad, 40, 3), statistics.stratum_sums(bad, w),
                          equal_nan=True)


@pytest.mark.parametrize('length', [5, 3])
def test_a_column_major_table_gives_the_same_sums_and_statistics(length):
    rec = recorded(stationary_protocol(samples=100),
                   [fx.TemporalDrift((0, 2), 0.03, 5.0), fx.SensorLatency((3,), 1)])
    rows = statistics.stationary_blocks(rec, rec.channels_used, length)
    cols = statistics.stationary_blocks(rec, rec.channels_used, length, column_major=True)
    assert cols.sums.flags['F_CONTIGUOUS'] and rows.sums.flags['C_CONTIGUOUS']
    assert np.array_equal(rows.sums, cols.sums)
    assert max(np.diff(rows.edges)) > 128           # strata of many blocks: pairwise sums
    by_rows, by_cols = statistics.compute(rows, 0), statistics.compute(cols, 0)
    assert by_rows.keys == by_cols.keys
    assert np.array_equal(by_rows.values, by_cols.values, equal_nan=True)
    assert np.array_equal(resample.stratum_sums(rows, np.ones((1, len(rows.stratum)))),
                          resample.stratum_sums(cols, np.ones((1, len(cols.stratum)))))


def test_a_part_of_the_table_is_written_in_place():
    packer = blocksums.Packer({'a': (2,), 'b': (3, 2)}, 4, np.arange(4), np.arange(4),
                              column_major=True)
    packer.view('b')[:, 1, 0] = 7.0
    assert packer.out[:, 2 + 2].tolist() == [7.0] * 4 and packer.out.sum() == 28.0


def _detached_plain(col, end, at_end, k) -> bool:
    """The value-apart test as it was: every reading filtered and negated first."""
    if np.count_nonzero(at_end[0] == k) < dropout.DETACHED_HITS:
        return False
    x = col[np.isfinite(col)]
    x = x if end == 0 else -x
    rest = x[x > x.min()]
    m = min(rest.size, 64 * (dropout.SPACINGS + 1))
    if m < dropout.SPACINGS + 1:
        return False
    near = np.unique(np.partition(rest, m - 1)[:m])[:dropout.SPACINGS + 1]
    if near.size < 3:
        return False
    gap = near[0] - x.min()
    return bool(gap >= dropout.AWAY and gap >= dropout.DETACHED * np.diff(near).max())


def test_the_value_apart_test_with_known_count_and_finiteness_is_the_plain_one():
    rng = np.random.default_rng(9)
    answers = set()
    for _ in range(400):
        x = _integer_columns(rng)
        if rng.random() < 0.3:          # a value lost beyond the noise's reach
            x[rng.integers(0, x.shape[0], 5), 0] = rng.choice([x.min() - 30, x.max() + 30])
        if rng.random() < 0.1:
            x[rng.integers(0, x.shape[0]), -1] = np.nan
        xt = np.ascontiguousarray(x.T)
        finite = bool(np.isfinite(x).all())
        for end in (0, 1):
            value = np.nanmin(x, axis=0) if end == 0 else np.nanmax(x, axis=0)
            hits = np.nonzero(xt == value[:, None])
            for k in range(x.shape[1]):
                count = int(np.count_nonzero(hits[0] == k))
                fast = dropout._detached(xt[k], end, hits, k, finite, count)
                assert fast == _detached_plain(xt[k], end, hits, k)
                answers.add(fast)
    assert answers == {True, False}
