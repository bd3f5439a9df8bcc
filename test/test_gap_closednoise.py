"""Closed-loop noise statistics (``gap.closednoise``): sensor effects seen while the
robot turns, in recordings that keep their headings (a tracked robot).

The 'robot' is the closed-loop simulator with hidden effects; the diagnosis sees only
the recording and the plain simulator's configuration.
"""
import numpy as np

from khepera_noise_ros.gap import closednoise, diagnose, loopchange, replay
from khepera_noise_ros.gap import effects as fx
from khepera_noise_ros.gap.target import Target
from test_gap_support import CONFIG, closed_loop_protocol

OPTIONS = diagnose.Options(config=CONFIG, replicates=60)
PAIR = (1, 6)                       # not adjacent


def tracked(effects, seed=5, episodes=24):
    """A closed-loop recording with its headings kept."""
    rec = replay.replay(closed_loop_protocol(episodes), CONFIG, effects, seed=seed)
    rec.manifest = dict(rec.manifest, source='emulator')
    assert np.isfinite(rec.heading_deg).all()
    return rec


def _z(c, family, sensors):
    return [z for k, z in zip(c.keys, c.z) if k.family == family and k.sensors == sensors]


def test_fast_noise_shared_by_a_pair_shows_and_is_fitted_with_that_pair():
    rec = tracked([fx.CorrelatedNoise((PAIR,), 0.03)])
    c = Target([rec], CONFIG, 1, replicates=60).compare()
    corr = _z(c, 'loop_residual_correlation', PAIR)
    assert corr and corr[0] > 6, corr
    others = [abs(z) for k, z in zip(c.keys, c.z)
              if k.family == 'loop_residual_correlation' and k.sensors != PAIR]
    assert max(others) < 6 * 1.5 and corr[0] > max(others)
    result = diagnose.diagnose([rec], OPTIONS)
    assert result.top_effect == 'correlated_noise', result.effects[:2]
    p = result.effects[0]['parameters']
    assert [sorted(g) for g in p['groups']] == [list(PAIR)]
    assert result.effects[0]['heldout_reduction'] > 0.8


def test_latency_and_a_shared_pair_are_both_chosen():
    """Latency dominates the closed-loop statistics; the pair rides along.  The heading
    residuals allow for readings that belong to an earlier heading, so the pair still
    shows once latency is in the simulator, and the compound adds it."""
    rec = tracked([fx.SensorLatency(tuple(range(8)), 1), fx.CorrelatedNoise((PAIR,), 0.03)])
    result = diagnose.diagnose([rec], OPTIONS)
    chosen = result.to_json()['compound']['chosen']
    names = [c['name'] for c in chosen]
    assert names == ['sensor_latency', 'correlated_noise'], (names, result.effects[:3])
    assert chosen[0]['sensors'] == list(range(8)) and chosen[0]['parameters']['steps'] == 1
    groups = chosen[1]['parameters']['groups']
    assert [sorted(g) for g in groups] == [list(PAIR)], groups
    assert abs(chosen[1]['parameters']['strength'] - 0.03) < 0.01


def test_a_spread_law_in_closed_loop_is_fitted_from_the_sensors_levels():
    """Noise growing with brightness: the front sensor facing the lamp (bright) gets far
    more than the dark ones; the law is fitted across sensors at their mean levels."""
    law = fx.IntensityDependentNoise(tuple(range(8)), 0.03, 1.0, 525.0, 1.5, 'bright', False)
    result = diagnose.diagnose([tracked([law])], OPTIONS)
    assert result.top_effect == 'intensity_dependent_noise', result.effects[:2]
    p = result.effects[0]['parameters']
    assert p['direction'] == 'bright' and p['strength'] > 0.01, p
    assert result.effects[0]['heldout_reduction'] > 0.8


def test_a_slow_shared_drift_in_closed_loop_is_temporal_drift():
    drift = fx.TemporalDrift(tuple(range(8)), 0.03, 30.0, True)
    result = diagnose.diagnose([tracked([drift])], OPTIONS)
    assert result.top_effect == 'temporal_drift', result.effects[:2]
    assert result.effects[0]['parameters']['shared']


def test_a_clean_recording_gives_no_significant_gap():
    """The simulator against itself: the noise statistics are there and agree (1 copy
    against 3: a bias with the amount of data would show here), no effect is named.
    The false-positive rate over 40 seeds is in docs/diagnosis.md."""
    for seed in (3, 8):
        rec = tracked([], seed=seed)
        result = diagnose.diagnose([rec], OPTIONS)
        out = result.to_json()
        assert not out['gap_significant'], out['where'][:3]
        assert out['top_effect'] == 'none' and out['compound'] is None
        families = {w['statistic'] for w in out['where']}
        assert families & closednoise.FAMILIES      # compared, and not significant


def test_heading_residuals_need_recorded_headings():
    rec = tracked([], episodes=8)
    families = {k.family for k in Target([rec], CONFIG, 1, replicates=20).real.keys}
    assert {'loop_residual_spread', 'loop_residual_correlation'} <= families
    assert not families & loopchange.FAMILIES     # tracked: the heading residuals alone
    rec.heading_deg[:] = np.nan          # a robot nobody tracked; it never stands still
    families = {k.family for k in Target([rec], CONFIG, 1, replicates=20).real.keys}
    assert not families & (closednoise.FAMILIES - loopchange.FAMILIES)
    assert loopchange.FAMILIES <= families       # only the change residuals are left
    assert 'closed_loop_level' in families


def test_still_pairs_measure_noise_alone():
    """Where the robot does not turn (power 0, no knock) the first differences are noise:
    their spread is the noise's and pairs sharing noise correlate."""
    rng = np.random.default_rng(0)
    rec = tracked([], episodes=6)
    rec.power[:] = 0
    rec.heading_deg[:] = np.nan
    light = np.linspace(100, 500, 8)
    noise = rng.normal(0, 4.0, (len(rec), 8))
    noise[:, 6] = 0.6 * noise[:, 1] + 0.8 * noise[:, 6]
    rec.readings[:] = light + noise
    from khepera_noise_ros.gap import statistics
    s = statistics.compute(statistics.closed_loop_blocks(rec, 5), 0)
    got = dict(zip(s.keys, s.estimate))
    spread = [v for k, v in got.items() if k.family == 'loop_still_spread']
    assert np.allclose(spread, 4.0, rtol=0.12), spread
    corr = {k.sensors: v for k, v in got.items() if k.family == 'loop_still_correlation'}
    assert abs(corr[PAIR] - 0.6) < 0.1 and abs(corr[(0, 1)]) < 0.1
