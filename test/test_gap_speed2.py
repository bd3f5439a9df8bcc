"""More shortcuts of the diagnosis held against the plain computations they replace.

The objective's memo, the dropout repair's shared geometry and partition, the cross
products packed as a triangle, the whole-row reorder of the block sums, the own-wander
parts remembered and a replay remembered with its repair: each gives the values of
the computation it replaces, bit for bit.  Speed is ``benchmark/bench_diagnose.py``'s.
"""
import numpy as np

from khepera_noise_ros.gap import dropout, fit, fitdrift, ownwander, resample, statistics, target
from khepera_noise_ros.gap import effects as fx
from khepera_noise_ros.gap.blocks import pack
from test_gap_support import CONFIG, recorded, stationary_protocol, sums_both_ways


def _count_replays(monkeypatch) -> list:
    calls = []
    plain = target.replay.replay
    monkeypatch.setattr(target.replay, 'replay',
                        lambda *a, **kw: calls.append(1) or plain(*a, **kw))
    return calls


def test_an_objective_is_computed_once_and_equals_the_plain_one(monkeypatch):
    rec = recorded(stationary_protocol(samples=12), [fx.TemporalDrift((1, 2), 0.02, 8.0)])
    t = target.Target([rec], CONFIG, seed=3)
    drift = fx.TemporalDrift((1, 2), 0.015, 6.0, True)
    calls = _count_replays(monkeypatch)
    target._REPLAYS.clear()
    first = t.objective([drift])
    assert len(calls) == 1
    target._REPLAYS.clear()             # a second ask is answered without a replay
    assert t.objective([drift]) == first and len(calls) == 1
    assert t._objective([drift], None, None, target.MARGIN, False) == first
    assert len(calls) == 2
    # anything that changes the value is part of the key: other effects, families,
    # the effects a copy is given, another seed on a copy
    other = fx.TemporalDrift((1, 2), 0.03, 6.0, True)
    assert t.objective([other]) == t._objective([other], None, None, target.MARGIN, False)
    assert t.objective([drift], families=('autocorrelation',)) == \
        t._objective([drift], None, ('autocorrelation',), target.MARGIN, False)
    given = t.with_given([other])
    assert given.objective([drift]) == given._objective([drift], None, None,
                                                        target.MARGIN, False)
    assert given.objective([drift]) != first
    reseeded = target.copy.copy(t)
    reseeded.seed = t.seed + 1
    assert reseeded.objective([drift]) == reseeded._objective([drift], None, None,
                                                              target.MARGIN, False)
    assert reseeded.objective([drift]) != first


def _scales_plain(col, run_of, first, sizes, wanted) -> np.ndarray:
    """1.4826 x each wanted run's median distance from the local levels, one run at a
    time with ``np.median``."""
    out = np.full(sizes.size, np.inf)
    for r in wanted:
        i = np.arange(first[r], first[r] + sizes[r])
        local = np.median(col[dropout._neighbours(run_of, first, sizes, dropout.NEAR, i)],
                          axis=0)
        d = np.abs(col[i] - local)
        out[r] = 1.4826 * np.median(np.where(np.isfinite(d), d, 0.0))
    return out


def _random_recording(rng):
    n, c = int(rng.integers(5, 300)), int(rng.integers(1, 5))
    episode = np.sort(rng.integers(0, rng.integers(1, 5), n))
    x = rng.normal(300, rng.choice([0.5, 3.0, 20.0]), (n, c))
    if rng.random() < 0.7:
        x = np.round(x)
    x[rng.random((n, c)) < rng.choice([0.0, 0.01, 0.05])] = rng.choice([0.0, 1023.0])
    if rng.random() < 0.1:
        x[rng.integers(0, n)] = np.nan
    runs = [np.flatnonzero(episode == e) for e in np.unique(episode)]
    return x, runs, bool(rng.random() < 0.3)


def test_repair_with_shared_local_levels_marks_what_the_plain_scales_mark(monkeypatch):
    rng = np.random.default_rng(5)
    cases = [_random_recording(rng) for _ in range(150)]
    fast = [dropout.repair(x, runs, moving) for x, runs, moving in cases]
    assert sum(int(f[1].sum()) for f in fast) > 100      # the marks are tested, not absent
    monkeypatch.setattr(dropout, '_scales', lambda col, run_of, first, sizes, wanted,
                        deviations=None: _scales_plain(col, run_of, first, sizes, wanted))
    for (x, runs, moving), f in zip(cases, fast):
        dropout._GEOMETRY.clear()
        plain = dropout.repair(x, [r.copy() for r in runs], moving)
        for a, b in zip(f, plain):
            assert np.array_equal(a, b, equal_nan=True)


def test_run_scales_from_shared_distances_equal_run_by_run_medians():
    rng = np.random.default_rng(6)
    for _ in range(60):
        x, runs, _ = _random_recording(rng)
        geometry = dropout._geometry(runs, x.shape[0])
        if geometry is None:
            continue
        order, sizes, first, run_of, _ = geometry
        col = x[order, 0]
        wanted = np.unique(rng.choice(sizes.size, size=int(rng.integers(1, sizes.size + 1))))
        plain = _scales_plain(col, run_of, first, sizes, wanted)
        for deviations in (None, dropout._deviations(col, run_of, first, sizes)):
            fast = dropout._scales(col, run_of, first, sizes, wanted, deviations)
            if np.all(col[np.isfinite(col)] == np.round(col[np.isfinite(col)])):
                assert np.array_equal(fast, plain)       # halves of integers: exact
            else:
                assert np.allclose(fast, plain, rtol=1e-12, atol=1e-9)


def test_repair_geometry_is_remembered_per_list_of_runs():
    rng = np.random.default_rng(8)
    x, runs, _ = _random_recording(rng)
    runs = runs + [np.arange(0)]
    first = dropout._geometry(runs, x.shape[0])
    assert dropout._geometry(runs, x.shape[0]) is first
    fresh = dropout._geometry([r.copy() for r in runs], x.shape[0])
    for a, b in zip(first, fresh):
        assert np.array_equal(a, b)
    assert dropout._geometry([np.arange(2)], 5) is None       # no run of 3 samples


def test_rows_reordered_whole_equal_each_part_taken_in_order():
    rng = np.random.default_rng(1)
    parts = {'n': rng.random((40, 1)), 'sx': rng.random((40, 3)),
             'sq': rng.random((40, 3, 3)), 'lag': rng.random((40, 2, 3))}
    order = rng.permutation(40)
    out, layout = pack(parts, 40, order)
    for name, value in parts.items():
        where, shape = layout[name]
        assert np.array_equal(out[:, where].reshape((40,) + shape), value[order])
    assert np.array_equal(pack(parts, 40)[0][order], out)


def test_cross_products_from_the_triangle_equal_the_full_block_sums():
    """The triangle summed per block then mirrored equals the full matrix of products
    summed per block, as the statistics used it; and every statistic of a recording is
    what the full matrix gives."""
    rec = recorded(stationary_protocol(samples=16), [fx.CorrelatedNoise(((0, 1, 2),), 0.03)])
    blocks = statistics.stationary_blocks(rec, rec.channels_used, 5)
    c = len(rec.channels_used)
    lay = statistics._layout(rec, 5)
    x = rec.readings[:, list(rec.channels_used)].astype(np.float64)
    y = np.empty_like(x)
    for r in lay['runs']:
        y[r] = x[r] - x[r].mean(axis=0)
    y32 = y[lay['order']].astype(np.float32)
    full = np.zeros((lay['nb'], c, c))
    for b in range(lay['nb']):
        rows = y32[lay['block'] == b]
        full[b] = (rows[:, :, None] * rows[:, None, :]).sum(axis=0, dtype=np.float32)
    full = full[lay['by_stratum']]
    mirrored = statistics._cross(blocks.part(blocks.sums, 's2'), c)
    assert np.allclose(mirrored, full, rtol=1e-6, atol=1e-3)
    assert np.array_equal(mirrored, mirrored.transpose(0, 2, 1))
    # the statistics: the same from the triangle as from the mirrored full matrix
    stats = statistics.compute(blocks, 30, 7)
    tri = blocks.layout['s2'][0]
    wide = np.concatenate([blocks.sums[:, :tri.start], mirrored.reshape(len(mirrored), -1),
                           blocks.sums[:, tri.stop:]], axis=1)
    shift = c * c - (tri.stop - tri.start)
    layout = {k: (slice(w.start + shift, w.stop + shift), shape) if w.start >= tri.stop
              else (w, shape) for k, (w, shape) in blocks.layout.items()}
    layout['s2'] = (slice(tri.start, tri.start + c * c), (c, c))
    wide_blocks = statistics.Blocks('stationary', blocks.channels, blocks.strata,
                                    blocks.stratum, wide, layout, blocks.extra)
    plain_cross = statistics._cross
    try:
        statistics._cross = lambda s2, channels: s2       # already full
        plain = statistics.compute(wide_blocks, 30, 7)
    finally:
        statistics._cross = plain_cross
    assert plain.keys == stats.keys
    assert np.array_equal(plain.values, stats.values, equal_nan=True)


def test_run_means_of_rows_in_run_order_equal_the_reordered_path():
    rec = recorded(stationary_protocol(samples=14), [fx.SensorLatency((1,), 1)])
    shortcut, general = sums_both_ways(rec, 4, 'runs_sorted')
    assert np.array_equal(shortcut.sums, general.sums)


def test_own_parts_remembered_only_for_unchanging_readings():
    rec = recorded(stationary_protocol(samples=40), [fx.TemporalDrift((0, 3), 0.03, 10.0)])
    plain = ownwander._own_parts(rec)
    assert rec.readings.flags.writeable
    got = ownwander._own(rec)                # writable, no memo: computed, not kept
    assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(got, plain))
    memo = {}
    kept = ownwander._own(rec, (0, 1, 2), memo)
    assert ownwander._own(rec, (0, 1, 2), memo) is kept
    assert all(np.array_equal(a, b, equal_nan=True)
               for a, b in zip(kept, ownwander._own_parts(rec, (0, 1, 2))))
    rec.readings[::7, 0] += 5.0              # changed in place: without a memo, seen
    changed = ownwander._own(rec)
    assert not np.array_equal(changed[0], plain[0], equal_nan=True)


def test_a_remembered_replay_is_the_repaired_replay(monkeypatch):
    rec = recorded(stationary_protocol(samples=12))
    effect = fx.SaturationQuantization((0, 1), dropout=0.05, dropout_value=0.0)
    t = target.Target([rec], CONFIG, seed=2)
    target._REPLAYS.clear()
    sim = t.simulate([effect])[0]
    calls = []
    monkeypatch.setattr(dropout, 'repair', lambda *a, **kw: calls.append(1))
    assert t.simulate([effect])[0] is sim and calls == []     # not repaired again
    monkeypatch.undo()
    fresh = target.replay.replay(rec, CONFIG, (effect,), seed=2, replicates=t.copies)
    repaired, marks, _ = dropout.repair(fresh.readings, dropout.episodes(fresh))
    assert marks.sum() > 0
    assert np.array_equal(sim.readings, repaired)
    assert np.array_equal(dropout.known(sim.readings)[0], marks)
    assert not sim.readings.flags.writeable


def test_lagged_products_of_shifted_rows_equal_the_gathered_pairs():
    rec = recorded(stationary_protocol(samples=15), [fx.TemporalDrift((0, 2), 0.03, 5.0)])
    shortcut = statistics.stationary_blocks(rec, rec.channels_used, 5)
    lay = statistics._layout(rec, 5)
    assert all(s is not None for s in lay['lag_shifts'])     # the shortcut was taken
    kept = lay['lag_shifts']
    lay['lag_shifts'] = [None] * len(kept)
    try:
        general = statistics.stationary_blocks(rec, rec.channels_used, 5)
    finally:
        lay['lag_shifts'] = kept
    assert np.array_equal(shortcut.sums, general.sums)
    # blocks longer than numpy adds in order keep the gathered pairs
    statistics.stationary_blocks(rec, rec.channels_used, statistics.SEQUENTIAL + 1)
    long_blocks = statistics._layout(rec, statistics.SEQUENTIAL + 1)
    assert all(s is None for s in long_blocks['lag_shifts'])


def test_remembered_selection_matrix_gives_the_sums_of_fresh_weights():
    recs = [recorded(stationary_protocol(samples=12), [fx.SensorLatency((1,), 1)], seed=s)
            for s in (1, 2)]
    resample._PICKS.clear()
    for rec in recs:        # the second recording's blocks meet the first one's matrix
        blocks = statistics.stationary_blocks(rec, rec.channels_used, 4)
        for replicates, seed in ((40, 3), (40, 4), (7, 3)):
            w = statistics.weights(blocks, replicates, np.random.default_rng(seed))
            assert np.array_equal(resample.resampled(blocks, replicates, seed),
                                  statistics.stratum_sums(blocks, w))
    assert len(resample._PICKS) == 3
    bad = statistics.stationary_blocks(recs[0], recs[0].channels_used, 4)
    bad.sums[0, 0] = np.inf              # a sum not finite: undrawn blocks are kept
    w = statistics.weights(bad, 40, np.random.default_rng(3))
    assert np.array_equal(resample.resampled(bad, 40, 3),
                          statistics.stratum_sums(bad, w), equal_nan=True)


def test_drift_on_every_sensor_in_place_equals_the_gathered_columns():
    level = np.random.default_rng(4).uniform(50, 500, (120, 8, 3))
    for shared in (True, False):
        drift = fx.TemporalDrift(tuple(range(8)), 0.02, 12.0, shared)
        out = drift.over_time(level, np.random.default_rng(9))
        rng = np.random.default_rng(9)
        z = rng.standard_normal((120, 1 if shared else 8, 3))
        a = np.exp(-1.0 / 12.0)
        z[0] *= 0.02
        z[1:] *= np.sqrt(1 - a * a) * 0.02
        state = np.zeros_like(z)
        state[0] = z[0]
        for t in range(1, 120):
            state[t] = a * state[t - 1] + z[t]
        plain = level.copy()
        plain[:, list(range(8))] *= 1.0 + state
        assert np.allclose(out, plain, rtol=1e-12, atol=0)
        reordered = fx.TemporalDrift(tuple(range(7, -1, -1)), 0.02, 12.0, shared)
        back = reordered.over_time(level, np.random.default_rng(9))
        plain = level.copy()
        plain[:, list(range(7, -1, -1))] *= 1.0 + state
        assert np.allclose(back, plain, rtol=1e-12, atol=0)


def test_columns_of_every_channel_are_the_readings_and_marks_unchanged():
    rec = recorded(stationary_protocol(samples=12),
                   [fx.SaturationQuantization((2,), dropout=0.05, dropout_value=0.0)])
    ready = dropout.prepared(rec)
    every = tuple(range(rec.readings.shape[1]))
    x, marks = dropout.columns(ready, every)
    assert np.array_equal(x, ready.readings.astype(np.float64)) and marks.sum() > 0
    assert np.array_equal(marks, dropout.known(ready.readings)[0])
    some, some_marks = dropout.columns(ready, (2, 0))
    assert np.array_equal(some, ready.readings[:, [2, 0]])
    assert np.array_equal(some_marks, dropout.known(ready.readings)[0][:, [2, 0]])
    fresh = dropout.repair(rec.readings.astype(np.float64), dropout.episodes(rec))
    assert np.array_equal(x, fresh[0]) and np.array_equal(marks, fresh[1])


def test_drift_search_in_the_own_wander_box_stops_within_the_objectives_noise(monkeypatch):
    """10 objectives where the own wander bounds the search: the answer's objective lies
    within the objective's spread between simulator seeds of the 16-objective answer's."""
    flicker = fx.IntensityDependentNoise(tuple(range(8)), 0.06, 2.0, 525.0, 0.0, 'dark', True)
    truth = fx.TemporalDrift((0, 2, 3, 5, 6), 0.01, 40.0, False)
    rec = recorded(stationary_protocol(samples=120), [truth, flicker], seed=11)
    t = target.Target([rec], CONFIG, 3, 'auto', replicates=40).with_given([flicker])
    c = t.compare(replicates=40)
    asked = []
    plain = fitdrift.minimize
    monkeypatch.setattr(fitdrift, 'minimize', lambda f, x0, **kw: asked.append(
        kw['options']['maxfev']) or plain(f, x0, **kw))
    short = fit.drift(t, c)
    monkeypatch.setattr(fitdrift, 'DRIFT_EVALUATIONS', (16, 16))
    full = fit.drift(t, c)
    assert asked == [10, 16] and short.effect is not None and full.effect is not None
    spread = []
    for k in range(1, 5):
        other = target.copy.copy(t)
        other.seed = t.seed + 1000 * k
        spread.append(other.objective([full.effect]))
    assert abs(t.objective([short.effect]) - t.objective([full.effect])) <= np.std(spread)
