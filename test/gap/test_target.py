"""Real recordings held against the simulator (``gap.target``): what a target remembers (its
replays, repaired once, its objectives and comparisons) is what it would compute afresh,
and is read-only."""
import numpy as np
import pytest

from khepera_noise_ros.effects import SaturationQuantization, SensorLatency, TemporalDrift
from khepera_noise_ros.gap import dropouts
from khepera_noise_ros.gap.protocol import episodes
from khepera_noise_ros.gap.replay import Replayer
from khepera_noise_ros.gap.target import Target
from khepera_noise_ros.testing.protocols import CONFIG, recorded, stationary_protocol


def _count_replays(monkeypatch) -> list:
    """The copies each replay from now on is asked for, one entry a replay."""
    calls = []
    plain = Replayer.replay
    monkeypatch.setattr(Replayer, 'replay', lambda self, effects=(), seed=0, copies=1:
                        calls.append(copies) or plain(self, effects, seed, copies))
    return calls


def test_replays_are_remembered_and_read_only():
    rec = recorded(stationary_protocol(samples=10))
    t = Target([rec], CONFIG, seed=4)
    effect = SensorLatency((0,), 1)
    first, again = t.simulate([effect])[0], t.simulate([effect])[0]
    assert first is again
    assert not first.recording.readings.flags.writeable
    with pytest.raises(ValueError):
        first.recording.readings[0, 0] = 1.0
    other = Target([rec], CONFIG, seed=5).simulate([effect])[0]
    assert other is not first
    assert not np.array_equal(other.recording.readings, first.recording.readings)
    # the remembered replay is the replay itself
    fresh = Replayer(rec, CONFIG).replay((effect,), seed=4, copies=t.copies)
    assert np.array_equal(fresh.readings, first.recording.readings)


def test_an_objective_is_computed_once_and_equals_a_fresh_targets(monkeypatch):
    rec = recorded(stationary_protocol(samples=12), [TemporalDrift((1, 2), 0.02, 8.0)])
    t = Target([rec], CONFIG, seed=3)
    drift = TemporalDrift((1, 2), 0.015, 6.0, True)
    calls = _count_replays(monkeypatch)
    first = t.objective([drift])
    assert len(calls) == 1
    t.memory.replays.clear()             # a second ask is answered without a replay
    assert t.objective([drift]) == first and len(calls) == 1

    def fresh():
        return Target([rec], CONFIG, seed=3)
    assert fresh().objective([drift]) == first
    # anything that changes the value is part of the key: other effects, families,
    # the effects a copy is given, another seed on a copy
    other = TemporalDrift((1, 2), 0.03, 6.0, True)
    assert t.objective([other]) == fresh().objective([other]) != first
    acf = frozenset({'autocorrelation'})
    assert t.objective([drift], families=acf) == fresh().objective([drift], families=acf) \
        != first
    given = t.with_given([other])
    assert given.objective([drift]) == fresh().with_given([other]).objective([drift])
    assert given.objective([drift]) != first
    reseeded = t.with_seed(t.seed + 1)
    assert reseeded.objective([drift]) == fresh().with_seed(t.seed + 1).objective([drift])
    assert reseeded.objective([drift]) != first


def test_a_comparison_is_made_once_and_equals_a_fresh_targets(monkeypatch):
    rec = recorded(stationary_protocol(samples=12), [TemporalDrift((1, 2), 0.02, 8.0)])
    t = Target([rec], CONFIG, seed=3, replicates=30)
    drift = TemporalDrift((1, 2), 0.015, 6.0, True)
    calls = _count_replays(monkeypatch)
    first = t.compare([drift])
    made = len(calls)
    t.memory.replays.clear()             # a second ask is answered without a replay
    assert t.compare([drift]) is first and len(calls) == made

    def same(a, b) -> bool:
        return a.keys == b.keys and all(np.array_equal(getattr(a, f), getattr(b, f),
                                                       equal_nan=True)
                                        for f in ('real', 'sim', 'se', 'z'))
    fresh = Target([rec], CONFIG, seed=3, replicates=30)
    assert same(fresh.compare([drift]), first)
    # the replicates, the effects a copy is given and its seed are part of the key
    fewer = t.compare([drift], replicates=10)
    assert fewer is not first and same(fewer, fresh.compare([drift], replicates=10))
    given = t.with_given([drift]).compare()
    assert given is first                # the same simulator: given or added, one comparison
    reseeded = t.with_seed(4).compare([drift])
    assert not same(reseeded, first) and same(reseeded, fresh.with_seed(4).compare([drift]))


@pytest.mark.parametrize('samples, copies', [(12, 3), (340, 1)])
def test_a_comparison_simulates_enough_samples_and_no_more(monkeypatch, samples, copies):
    """A short recording is compared on three simulated copies of its protocol; one of over
    13,333 samples on one copy, as its objectives are."""
    rec = recorded(stationary_protocol(samples=samples))
    t = Target([rec], CONFIG, seed=1, replicates=10)
    asked = _count_replays(monkeypatch)
    t.compare()
    t.objective()
    assert asked and set(asked) == {copies}, (len(rec), asked)


def test_a_remembered_replay_is_the_repaired_replay(monkeypatch):
    rec = recorded(stationary_protocol(samples=12))
    effect = SaturationQuantization((0, 1), dropout=0.05, dropout_value=0.0)
    t = Target([rec], CONFIG, seed=2)
    sim = t.simulate([effect])[0]
    calls = []
    monkeypatch.setattr(dropouts, 'repair', lambda *a, **kw: calls.append(1))
    assert t.simulate([effect])[0] is sim and calls == []     # not repaired again
    monkeypatch.undo()
    fresh = Replayer(rec, CONFIG).replay((effect,), seed=2, copies=t.copies)
    repaired, marks, _ = dropouts.repair(fresh.readings,
                                         dropouts.Runs(episodes(fresh), len(fresh)))
    assert marks.sum() > 0
    assert np.array_equal(sim.recording.readings, repaired)
    assert np.array_equal(sim.marks, marks)
    assert not sim.recording.readings.flags.writeable
