"""The diagnosis's shortcuts give the values of the plain computations they replace.

Each test holds a fast path (``gap.statistics``, ``gap.effects``, ``gap.target``,
``gap.compound._backfit``) against a direct computation written here the simple way,
bit for bit where the shortcut claims it.  Speed itself is measured by
``benchmark/bench_diagnose.py``, not here.
"""
import numpy as np
import pytest
from scipy import sparse

from khepera_noise_ros.gap import blockcounts, blocklength, compound, fit, statistics, target
from khepera_noise_ros.gap import effects as fx
from khepera_noise_ros.gap.blocks import Blocks, pack
from khepera_noise_ros.gap.fitbase import Candidate
from test_gap_support import CONFIG, recorded, stationary_protocol, sums_both_ways


def _blocks(rng, strata=5, per=(0, 1, 3, 7, 12), width=6, bad=False) -> Blocks:
    """Blocks in shuffled stratum order, one stratum with none."""
    stratum = np.concatenate([np.full(per[s % len(per)], s) for s in range(strata)])
    rng.shuffle(stratum)
    sums = rng.normal(size=(stratum.size, width)) * 10.0 ** rng.integers(-3, 4, width)
    if bad:
        sums[1, 2] = np.nan
    parts, _ = pack({'x': sums}, stratum.size)
    return Blocks('stationary', (0,), [f's{s}' for s in range(strata)], stratum, parts,
                  {'x': (slice(0, width), (width,))})


def _weights_plain(blocks: Blocks, replicates: int, rng) -> np.ndarray:
    w = np.zeros((1 + replicates, blocks.stratum.size))
    w[0] = 1.0
    for lo, hi in zip(blocks.edges[:-1], blocks.edges[1:]):
        if replicates and hi > lo:
            picks = rng.integers(lo, hi, size=(replicates, hi - lo))
            rows = np.repeat(np.arange(1, replicates + 1), hi - lo)
            np.add.at(w, (rows, picks.ravel()), 1.0)
    return w


def _sums_plain(blocks: Blocks, w: np.ndarray) -> np.ndarray:
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
    for replicates in (0, 1, 40):
        w = statistics.weights(blocks, replicates, np.random.default_rng(11))
        plain = _weights_plain(blocks, replicates, np.random.default_rng(11))
        assert np.array_equal(w, plain)
        assert w[1:].sum() == replicates * blocks.stratum.size
        if replicates:
            assert np.array_equal(statistics.stratum_sums(blocks, w), _sums_plain(blocks, w),
                                  equal_nan=True)


def _residue_plain(x: np.ndarray) -> np.ndarray:
    """(N, C, moduli) 1 where a reading lies on its channel's most common residue."""
    out = np.zeros(x.shape + (len(statistics.MODULI),))
    for k in range(x.shape[1]):
        for j, q in enumerate(statistics.MODULI):
            r = np.mod(x[:, k].astype(np.int64), q)
            out[:, k, j] = r == np.bincount(r, minlength=q).argmax()
    return out


def _mode_plain(x: np.ndarray, cell: np.ndarray) -> np.ndarray:
    out = np.zeros(x.shape)
    for c in np.unique(cell):
        at = cell == c
        for k in range(x.shape[1]):
            values, counts = np.unique(x[at, k], return_counts=True)
            out[at, k] = x[at, k] == values[np.argmax(counts)]
    return out


@pytest.mark.parametrize('samples,length', [(20, 5), (40, 150)])   # packed, plain counts
def test_mode_and_residue_counts_equal_reading_by_reading_counts(samples, length):
    rec = recorded(stationary_protocol(samples=samples), [fx.SaturationQuantization(
        (0, 1, 2, 3), step=4.0, origin=1.0)])
    b = statistics.stationary_blocks(rec, rec.channels_used, length)
    lay = statistics._layout(rec, length)
    assert (lay['largest'] >= 1 << blockcounts.DIGIT) == (length > 100)
    per_block = np.zeros((lay['nb'],) + rec.readings.shape[1:] + (len(statistics.MODULI),))
    np.add.at(per_block, lay['block'], _residue_plain(rec.readings)[lay['order']])
    modes = np.zeros((lay['nb'], rec.readings.shape[1]))
    np.add.at(modes, lay['block'], _mode_plain(rec.readings, lay['cell'])[lay['order']])
    order = np.argsort(lay['stratum'], kind='stable')      # Blocks sorts by stratum
    assert np.array_equal(b.part(b.sums, 'residue'), per_block[order])
    assert np.array_equal(b.part(b.sums, 'at_mode'), modes[order])
    edges = np.zeros((lay['nb'],) + rec.readings.shape[1:] + (2,))
    np.add.at(edges, lay['block'], statistics.pileup.edge_hits(rec.readings)[lay['order']])
    assert np.array_equal(b.part(b.sums, 'edge'), edges[order])
    on_lattice = b.part(b.sums, 'residue')[:, :4, statistics.MODULI.index(4)].sum()
    assert on_lattice > 0.9 * 4 * len(rec)          # the quantised sensors sit on it


@pytest.mark.parametrize('steps', [0, 1, 2, 5, 40])
@pytest.mark.parametrize('sensors', [(1, 4), tuple(range(8))])
def test_latency_over_time_is_the_late_sample(steps, sensors):
    level = np.random.default_rng(steps).normal(size=(30, 8, 3))
    out = fx.SensorLatency(sensors, steps).over_time(level, None)
    late = np.maximum(np.arange(30) - steps, 0)
    plain = level.copy()
    plain[:, list(sensors)] = level[late][:, list(sensors)]
    assert np.array_equal(out, plain)


@pytest.mark.parametrize('held', [True, False])
def test_intensity_over_time_equals_the_law_at_every_sample(held):
    rng = np.random.default_rng(5)
    level = rng.uniform(0, 525, size=(90, 8, 4))
    if held:                  # runs of 30 samples at one light level, as a replay's light
        level = np.repeat(level[::30], 30, axis=0)
    effect = fx.IntensityDependentNoise((0, 2, 5), 0.04, 2.5, constant=0.5, shared=False)
    out = effect.over_time(level, np.random.default_rng(1))
    z = np.random.default_rng(1).standard_normal((90, 3, 4))
    plain = level.copy()
    plain[:, [0, 2, 5]] += z * effect.amplitude(level[:, [0, 2, 5]])
    assert np.array_equal(out, plain)


def test_replays_are_remembered_and_read_only():
    rec = recorded(stationary_protocol(samples=10))
    t = target.Target([rec], CONFIG, seed=4)
    effect = fx.SensorLatency((0,), 1)
    first, again = t.simulate([effect])[0], t.simulate([effect])[0]
    assert first is again
    assert not first.readings.flags.writeable
    with pytest.raises(ValueError):
        first.readings[0, 0] = 1.0
    other = target.Target([rec], CONFIG, seed=5).simulate([effect])[0]
    assert other is not first and not np.array_equal(other.readings, first.readings)
    # the remembered replay is the replay itself
    fresh = target.replay.replay(rec, CONFIG, (effect,), seed=4, replicates=t.copies)
    assert np.array_equal(fresh.readings, first.readings)


def test_backfit_does_not_weigh_a_refit_that_is_the_effect_it_had(monkeypatch):
    rec = recorded(stationary_protocol(samples=10))
    a = target.Target([rec], CONFIG, seed=1)
    chosen = [fx.SensorGainOffset((0,), (1.1,), (2.0,)), fx.SensorLatency((1,), 1)]
    calls = []
    monkeypatch.setattr(fit, 'fit_one', lambda name, given, c: Candidate(
        name, next(e for e in chosen if e.name == name), 'same'))
    monkeypatch.setattr(target.Target, 'objective',
                        lambda self, effects=(), **kw: calls.append(effects) or 0.0)
    assert compound._backfit(a, chosen) == chosen
    assert calls == []
    # a refit that differs is weighed: both objectives are asked for
    changed = fx.SensorGainOffset((0,), (1.2,), (2.0,))
    monkeypatch.setattr(fit, 'fit_one', lambda name, given, c: Candidate(name, changed, ''))
    compound._backfit(a, chosen)
    assert len(calls) == 2


def test_block_sums_of_rows_in_order_equal_the_general_path():
    """A recording in step order takes the shortcut (no reordering of its rows); the
    general path, which reorders, gives the same sums."""
    rec = recorded(stationary_protocol(samples=20), [fx.SensorLatency((2,), 1)])
    shortcut, general = sums_both_ways(rec, 5, 'sorted')
    assert np.array_equal(shortcut.sums, general.sums)
    shuffled = rec.select(np.random.default_rng(0).permutation(len(rec)))
    other = statistics.stationary_blocks(shuffled, rec.channels_used, 5)
    assert not statistics._layout(shuffled, 5)['sorted']
    assert np.array_equal(np.sort(other.sums, axis=0), np.sort(shortcut.sums, axis=0))


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
    assert np.allclose(blocklength.autocovariance(x, segments, 150), plain, rtol=0,
                       atol=1e-12 * np.abs(plain).max())
    assert blocklength.block_length(x, segments[::2], 1, 100) > 5     # the walk needs long
