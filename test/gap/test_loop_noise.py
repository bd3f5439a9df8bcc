"""Sensor effects seen in closed-loop recordings: shared fast noise, a spread law and a
drift while the robot turns, beside a latency or a turn error, with headings recorded
(a tracked robot) or not (a robot that logs only while it runs its task).

The 'robot' is the closed-loop simulator with hidden effects; the diagnosis sees only
the recording and the plain simulator's configuration.
"""
import numpy as np

from khepera_noise_ros.effects import (ActuatorTurnError, CorrelatedNoise,
                                       IntensityDependentNoise, SensorLatency, TemporalDrift)
from khepera_noise_ros.gap import diagnose, evidence
from khepera_noise_ros.gap.families import of_part
from khepera_noise_ros.gap.target import Target
from khepera_noise_ros.testing.protocols import CONFIG, closed_loop_protocol, recorded, tracked

OPTIONS = diagnose.Options(config=CONFIG, replicates=60)
NOISE = of_part('closed_loop_noise')
CHANGE = frozenset(f for f in NOISE if f.startswith('loop_change_'))


def _z(c, family, sensors):
    return [z for k, z in zip(c.keys, c.z) if k.family == family and k.sensors == sensors]


def _chosen(rec):
    out = diagnose.diagnose([rec], diagnose.Options(config=CONFIG, replicates=60,
                                                    remainder=False)).to_json()
    return out['compound']['chosen']


# -- tracked: headings recorded ---------------------------------------------------------

def test_fast_noise_shared_by_a_pair_shows_and_is_fitted_with_that_pair():
    pair = (1, 6)
    rec = tracked(closed_loop_protocol(24), [CorrelatedNoise((pair,), 0.03)], seed=5)
    c = Target([rec], CONFIG, 1, replicates=60).compare()
    corr = _z(c, 'loop_residual_correlation', pair)
    assert corr and corr[0] > 6, corr
    others = [abs(z) for k, z in zip(c.keys, c.z)
              if k.family == 'loop_residual_correlation' and k.sensors != pair]
    assert max(others) < 6 * 1.5 and corr[0] > max(others)
    result = diagnose.diagnose([rec], OPTIONS)
    assert result.top_effect == 'correlated_noise', result.effects[:2]
    p = result.effects[0]['parameters']
    assert [sorted(g) for g in p['groups']] == [list(pair)]
    assert result.effects[0]['heldout_reduction'] > 0.8


def test_latency_and_a_shared_pair_are_both_chosen():
    """Latency dominates the closed-loop statistics; the pair rides along.  The heading
    residuals allow for readings that belong to an earlier heading, so the pair still
    shows once latency is in the simulator, and the compound adds it."""
    pair = (1, 6)
    rec = tracked(closed_loop_protocol(24), [SensorLatency(tuple(range(8)), 1),
                                             CorrelatedNoise((pair,), 0.03)], seed=5)
    result = diagnose.diagnose([rec], OPTIONS)
    chosen = result.to_json()['compound']['chosen']
    names = [c['name'] for c in chosen]
    assert names == ['sensor_latency', 'correlated_noise'], (names, result.effects[:3])
    assert chosen[0]['sensors'] == list(range(8)) and chosen[0]['parameters']['steps'] == 1
    groups = chosen[1]['parameters']['groups']
    assert [sorted(g) for g in groups] == [list(pair)], groups
    assert abs(chosen[1]['parameters']['strength'] - 0.03) < 0.01


def test_a_spread_law_in_closed_loop_is_fitted_from_the_sensors_levels():
    """Noise growing with brightness: the front sensor facing the lamp (bright) gets far
    more than the dark ones; the law is fitted across sensors at their mean levels."""
    law = IntensityDependentNoise(tuple(range(8)), 0.03, 1.0, 525.0, 1.5, 'bright', False)
    result = diagnose.diagnose([tracked(closed_loop_protocol(24), [law], seed=5)], OPTIONS)
    assert result.top_effect == 'intensity_dependent_noise', result.effects[:2]
    p = result.effects[0]['parameters']
    assert p['direction'] == 'bright' and p['strength'] > 0.01, p
    assert result.effects[0]['heldout_reduction'] > 0.8


def test_a_slow_shared_drift_in_closed_loop_is_temporal_drift():
    drift = TemporalDrift(tuple(range(8)), 0.03, 30.0, True)
    result = diagnose.diagnose([tracked(closed_loop_protocol(24), [drift], seed=5)], OPTIONS)
    assert result.top_effect == 'temporal_drift', result.effects[:2]
    assert result.effects[0]['parameters']['shared']


def test_a_clean_recording_gives_no_significant_gap():
    """The simulator against itself: the noise statistics are there and agree (1 copy
    against 3: a bias with the amount of data would show here), no effect is named.
    The false-positive rate over 40 seeds is in docs/diagnosis.md."""
    for seed in (3, 8):
        rec = tracked(closed_loop_protocol(24), seed=seed)
        result = diagnose.diagnose([rec], OPTIONS)
        out = result.to_json()
        assert not out['gap_significant'], out['where'][:3]
        assert out['top_effect'] == 'none' and out['compound'] is None
        families = {w['statistic'] for w in out['where']}
        assert families & NOISE      # compared, and not significant


def test_a_pair_beside_a_three_step_latency_on_some_sensors_is_chosen():
    """Each sensor's heading residuals taken at its own delay: the noise's shape still
    shows beside a latency of up to three steps."""
    pair = (1, 4)
    rec = tracked(closed_loop_protocol(20), [SensorLatency((0, 1, 2, 3, 4), 3),
                                             CorrelatedNoise((pair,), 0.03)], seed=5)
    result = diagnose.diagnose([rec], OPTIONS)
    chosen = result.to_json()['compound']['chosen']
    by = {c['name']: c for c in chosen}
    assert sorted(by) == ['correlated_noise', 'sensor_latency'], list(by)
    assert by['sensor_latency']['parameters']['steps'] == 3
    groups = by['correlated_noise']['parameters']['groups']
    assert [sorted(g) for g in groups] == [list(pair)], groups


def test_a_latency_alone_gains_no_sensor_effect():
    rec = tracked(closed_loop_protocol(20), [SensorLatency((0, 1, 2, 3, 4), 3)], seed=7)
    result = diagnose.diagnose([rec], OPTIONS)
    out = result.to_json()
    names = [c['name'] for c in out['compound']['chosen']] if out['compound'] else \
        [out['top_effect']]
    assert names == ['sensor_latency'], names


# -- short recordings: shared noise stronger than the old search range ------------------

STRONG = (3, 7)                     # not adjacent
STRENGTH = 0.04                     # above 0.03, the old search's ceiling


def _moment(target, c, pair):
    """The correlated noise fitter's start in closed loop: the pair's excess variance in
    the closed loop's spreads over their squared level (None without an excess)."""
    cells = target.evidence(c).spread_cells(pair, closed_loop=True)
    level = np.array([v for v, _ in cells])
    excess = max(float(np.sum([e for _, e in cells])), 0.0)
    return float(np.sqrt(excess / np.sum(level * level))) if excess > 0 else None


def test_shared_noise_strength_is_fitted_beyond_the_default_range():
    rec = tracked(closed_loop_protocol(10), [CorrelatedNoise((STRONG,), STRENGTH)], seed=1005)
    target = Target([rec], CONFIG, 1, replicates=60)
    c = target.compare(replicates=40)
    start = _moment(target, c, STRONG)
    assert start is not None and 0.5 * STRENGTH < start < 1.5 * STRENGTH, start
    cand = CorrelatedNoise.fit(target.evidence(c))
    assert [sorted(g) for g in cand.effect.groups] == [list(STRONG)], cand.effect
    # the old search could not leave [0.01 / 3, 0.01 * 3]; 10 episodes fix the size to ~25%
    assert cand.effect.strength > 0.033, cand.effect
    assert abs(cand.effect.strength - STRENGTH) < 0.3 * STRENGTH, cand.effect


def test_no_spread_no_start():
    """A clean recording gives no moment estimate (or a small one): the default stays."""
    rec = tracked(closed_loop_protocol(10), seed=1006)
    target = Target([rec], CONFIG, 1, replicates=60)
    c = target.compare(replicates=40)
    start = _moment(target, c, STRONG)
    assert start is None or start < 0.02, start


def test_turn_error_and_strong_shared_pair_are_chosen_by_name():
    """The case ``benchmark/closed_noise.py --episodes 10 --seed 1`` missed (case 5): the
    capped correlated_noise fit lost to a shared-draw spread law on the same pair."""
    hidden = [ActuatorTurnError(0.7, 0.0), CorrelatedNoise((STRONG,), STRENGTH)]
    rec = tracked(closed_loop_protocol(10), hidden, seed=1005)
    out = diagnose.diagnose([rec], diagnose.Options(config=CONFIG, replicates=60)).to_json()
    chosen = out['compound']['chosen']
    assert [s['name'] for s in chosen] == ['actuator_turn_error', 'correlated_noise'], chosen
    assert [sorted(g) for g in chosen[1]['parameters']['groups']] == [list(STRONG)]
    assert np.isclose(chosen[1]['parameters']['strength'], STRENGTH, rtol=0.3)


# -- loop only: no headings, never still ------------------------------------------------

LOOP_PAIR = (0, 3)                   # not adjacent; both read dark much of the time
LATENCY = SensorLatency(tuple(range(8)), 2)
SHARED = CorrelatedNoise((LOOP_PAIR,), 0.02)


def _loop_only(effects, seed):
    return recorded(closed_loop_protocol(25), effects, seed=seed)


def test_a_shared_pair_shows_beside_the_latency_and_a_clean_loop_does_not():
    given = Target([_loop_only([LATENCY, SHARED], seed=12)], CONFIG, 3, replicates=60)
    c = given.compare([LATENCY], replicates=60)
    z = {k: v for k, v in zip(c.keys, c.z) if k.family == 'loop_change_correlation'}
    pair = [v for k, v in z.items() if k.sensors == LOOP_PAIR]
    assert pair and pair[0] > 4, z
    found = evidence.loop_group_evidence(c.rows, range(8), 'fast')
    assert found[LOOP_PAIR] == found.max(), found
    clean = Target([_loop_only([LATENCY], seed=13)], CONFIG, 3, replicates=60)
    c0 = clean.compare([LATENCY], replicates=60)
    zs = np.array([v for k, v in zip(c0.keys, c0.z) if k.family in CHANGE])
    assert zs.size > 30 and np.nanmax(np.abs(zs)) < 4.5, zs


def test_latency_and_shared_pair_are_both_chosen_and_a_clean_latency_alone():
    chosen = _chosen(_loop_only([LATENCY, SHARED], seed=14))
    names = [s['name'] for s in chosen]
    assert names[0] == 'sensor_latency' and 'correlated_noise' in names, chosen
    groups = chosen[names.index('correlated_noise')]['parameters']['groups']
    assert [sorted(g) for g in groups] == [list(LOOP_PAIR)], groups
    clean = _chosen(_loop_only([LATENCY], seed=15))         # control: no false sensor effect
    assert [s['name'] for s in clean] == ['sensor_latency'], clean
