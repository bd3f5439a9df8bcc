"""The memo of simulated statistics in ``gap.target.Target``: the same answers as
without it, a bounded size, and no sharing between targets of different seeds."""
import copy

import numpy as np

from khepera_noise_ros.gap import effects as fx
from khepera_noise_ros.gap.target import Target
from test_gap_support import CONFIG, recorded, stationary_protocol

HIDDEN = [fx.TemporalDrift(tuple(range(8)), 0.02, 40.0, True)]
CANDIDATES = [(), (fx.CorrelatedNoise(((0, 1),), 0.02),),
              (fx.SensorGainOffset((2,), (1.1,), (5.0,)),),
              (fx.CorrelatedNoise(((0, 1),), 0.02),)]        # a repeat: served from the memo


def _recs():
    return [recorded(stationary_protocol(samples=20), HIDDEN, seed=3)]


def test_memoised_objective_and_compare_equal_the_uncached_ones():
    recs = _recs()
    cached = Target(recs, CONFIG, replicates=30)
    plain = Target(recs, CONFIG, replicates=30, cache_size=0)
    for effects in CANDIDATES:
        assert cached.objective(effects) == plain.objective(effects)
        a, b = cached.compare(effects), plain.compare(effects)
        assert a.keys == b.keys
        np.testing.assert_array_equal(a.z, b.z)
    assert len(plain._cache) == 0
    assert len(cached._cache) == 6       # 3 distinct sets x (objective, compare)
    joint = cached.with_given(CANDIDATES[1])
    assert joint.objective(CANDIDATES[2]) == plain.with_given(CANDIDATES[1]).objective(
        CANDIDATES[2])


def test_the_memo_is_bounded_and_keyed_by_seed():
    target = Target(_recs(), CONFIG, replicates=30, cache_size=2)
    for effects in CANDIDATES:
        target.objective(effects)
    assert len(target._cache) == 2
    other = Target(_recs(), CONFIG, replicates=30, seed=9, cache_size=0)
    target.objective(CANDIDATES[1])
    moved = copy.copy(target)    # shares the memo
    moved.seed = 9               # as the compound's confirmation does on a shallow copy
    moved._real = other._real
    assert moved.objective(CANDIDATES[1]) == other.objective(CANDIDATES[1])
