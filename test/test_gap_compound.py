"""Compound diagnosis: several effects at once, found as a set, and what is left.

The 'robot' is the simulator with hidden effects (``test_gap_support.recorded``);
the diagnosis sees only the recording and the plain simulator's configuration.
"""
import numpy as np
import pytest

from khepera_noise_ros.gap import diagnose, fit, remainder, replay
from khepera_noise_ros.gap import effects as fx
from khepera_noise_ros.simconfig import SimConfig
from khepera_noise_ros.gap.target import Target
from test_gap_support import CONFIG, recorded, stationary_protocol

OPTIONS = diagnose.Options(config=CONFIG, replicates=60)
PAIRS = ((0, 5), (1, 3), (2, 7), (4, 6))        # not adjacent: found from data alone


def test_pairs_of_fast_noise_and_a_slow_shared_change_come_out_as_two_effects():
    """Sensors share fast noise in pairs while a slow change (room light) moves all of
    them: the groups are the pairs, the slow change is temporal_drift shared by all,
    and the compound shrinks the held-out discrepancy by at least 0.7."""
    hidden = [fx.CorrelatedNoise(PAIRS, 0.02), fx.TemporalDrift(tuple(range(8)), 0.02, 40.0, True)]
    result = diagnose.diagnose([recorded(stationary_protocol(samples=60), hidden, seed=5)],
                               OPTIONS)
    chosen = result.to_json()['compound']['chosen']
    names = [c['name'] for c in chosen]
    assert set(names) == {'correlated_noise', 'temporal_drift'}, names
    groups = next(c for c in chosen if c['name'] == 'correlated_noise')['parameters']['groups']
    assert sorted(map(sorted, groups)) == sorted(map(list, PAIRS))
    drift = next(c for c in chosen if c['name'] == 'temporal_drift')
    assert drift['parameters']['shared'] and drift['sensors'] == list(range(8))
    assert result.compound.reduction >= 0.7
    # added shrinks add up to the cumulative one, in order
    assert abs(chosen[-1]['cumulative_reduction'] - sum(c['added_reduction'] for c in chosen)) \
        < 1e-9
    # the compound is what the simulator gets, and it beats the best single effect
    assert [e.name for e in result.fitted_effects] == names
    assert result.compound.reduction > result.effects[0]['heldout_reduction']
    assert result.to_json()['top_effect'] == result.effects[0]['name']


def test_a_single_effect_is_not_padded_with_others():
    hidden = [fx.CorrelatedNoise(((1, 2, 3),), 0.02)]
    result = diagnose.diagnose([recorded(stationary_protocol(samples=20), hidden, seed=5)],
                               OPTIONS)
    assert [c['name'] for c in result.to_json()['compound']['chosen']] == ['correlated_noise']


def test_the_remainder_says_what_is_off_and_the_empirical_model_closes_it():
    """Per-sensor noise largest at middling levels (no spread law is a hump): the named
    effects leave part of it; the empirical model, fitted on one part, shrinks the
    held-out discrepancy further and loads as an effect."""
    hump = fx.EmpiricalNoise(tuple(range(8)), (0.0, 200.0, 300.0, 525.0),
                             tuple([0.5, 12.0, 12.0, 0.5] * 8))
    result = diagnose.diagnose([recorded(stationary_protocol(samples=40), [hump], seed=5)],
                               OPTIONS)
    rem = result.to_json()['remainder']
    assert rem is not None and 'empirical' in rem
    assert rem['heldout_reduction_with_empirical'] > rem['heldout_reduction_named']
    assert rem['heldout_reduction_with_empirical'] > 0.5
    loaded = fx.loads(fx.dumps([result.empirical]))[0]
    assert loaded == result.empirical
    assert rem['where'] and rem['named_effects'] is not None


def test_the_empirical_model_measures_a_known_remainder():
    hidden = fx.EmpiricalNoise((0, 1, 2), (0.0, 525.0), (6.0, 6.0) * 3)
    rec = recorded(stationary_protocol(samples=60), [hidden], seed=3)
    model = remainder.fit(Target([rec], CONFIG, 1, replicates=20))
    spread = np.asarray(model.spread).reshape(8, -1)
    assert np.all(np.abs(spread[:3] - 6.0) < 2.0), spread[:3]
    assert spread[3:].mean() < 1.5 and spread[3:].max() < 4.0, spread[3:]   # chance only


def test_over_time_matches_the_stepwise_process():
    """The vectorised replay is the same process as the step-by-step one."""
    rng = np.random.default_rng(0)
    level = rng.uniform(50, 500, (30, 8, 4))
    for effect in (fx.SensorLatency((1, 2), 2), fx.SensorGainOffset((3,), (1.1,), (4.0,)),
                   fx.SaturationQuantization((0, 5), 40.0, 400.0, 4.0)):
        step = effect.process(4, 8, rng)
        stepwise = np.stack([step(level[t]) for t in range(30)])
        np.testing.assert_allclose(effect.over_time(level, rng), stepwise)
    drift = fx.TemporalDrift((0,), 0.05, 10.0, True)
    flat = np.full((20000, 8, 1), 100.0)
    out = drift.over_time(flat, np.random.default_rng(1))[:, 0, 0] / 100.0 - 1.0
    assert abs(out.std() - 0.05) < 0.01
    lag1 = np.corrcoef(out[:-1], out[1:])[0, 1]
    assert abs(lag1 - np.exp(-0.1)) < 0.03


def test_replay_of_an_empirical_effect_runs_in_the_closed_loop_simulator_too():
    from khepera_noise_ros.gap.simulate import EffectEpisodes
    from test_gap_support import closed_loop_protocol
    e = fx.EmpiricalNoise(tuple(range(8)), (0.0, 525.0), (3.0, 3.0) * 8)
    rec = replay.replay(closed_loop_protocol(4), SimConfig(), [e], seed=1)
    assert np.isfinite(rec.readings).all()
    EffectEpisodes(effects=[e]).reset(np.arange(3))


def test_a_spread_law_growing_with_brightness_is_fitted_with_its_parameters():
    """The flicker of the vocabulary grows with darkness; this noise grows with
    brightness, per sensor, with a constant part: the law's direction, power and
    constant come out, and it removes most of the held-out gap."""
    law = fx.IntensityDependentNoise(tuple(range(8)), 0.03, 1.0, 525.0, 1.5, 'bright', False)
    result = diagnose.diagnose([recorded(stationary_protocol(samples=40), [law], seed=5)],
                               OPTIONS)
    assert result.top_effect == 'intensity_dependent_noise', result.effects[:2]
    p = result.effects[0]['parameters']
    assert p['direction'] == 'bright' and not p['shared']
    assert abs(p['exponent'] - 1.0) <= 0.5 and p['constant'] < 4.0
    assert result.effects[0]['heldout_reduction'] > 0.8


def test_latency_and_an_offset_lattice_are_found_together():
    """Readings on the lattice 3 + 7k on every sensor, and four sensors a sample late."""
    hidden = [fx.SaturationQuantization(tuple(range(8)), step=7.0, origin=3.0),
              fx.SensorLatency((0, 1, 2, 3), 1)]
    result = diagnose.diagnose([recorded(stationary_protocol(samples=30), hidden, seed=5)],
                               OPTIONS)
    chosen = {c['name']: c for c in result.to_json()['compound']['chosen']}
    assert set(chosen) == {'sensor_latency', 'saturation_quantization'}
    assert chosen['saturation_quantization']['parameters']['step'] == 7.0
    assert chosen['saturation_quantization']['parameters']['origin'] == 3.0
    assert chosen['sensor_latency']['sensors'] == [0, 1, 2, 3]
    assert result.compound.reduction > 0.9


EMULATED_EPISODES = 120     # a 10% turn slip and 0.92 scale show in 120 episodes, not in 30
EMULATED_LONG = 240         # samples per heading: the robot's own drift of 0.4% shows


def _emulated_robot_recordings(seed: int = 3, episodes: int = EMULATED_EPISODES,
                               samples: int = 60):
    """Stationary and closed-loop recordings of the emulated robot with its default
    effects, recorded as the blind benchmark records them (more closed-loop episodes
    than its 30: ``benchmark/emulated_set.py`` measures what each effect needs)."""
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'benchmark'))
    from blind_gap import STATIONARY, record_closed_loop, record_stationary, robot
    from khepera_noise_ros.reality.effects import EffectsConfig
    from test_gap_support import GENOME
    config = EffectsConfig.real_robot()
    world = robot(config, seed)
    return config, [record_stationary(world, STATIONARY, samples=samples),
                    record_closed_loop(world, np.array(GENOME), episodes=episodes, seed=seed)]


@pytest.fixture(scope='module')
def emulated():
    """The diagnosis of the robot at 240 samples per heading, where its group noise shows
    (``benchmark/emulated_set.py``; a long recording is replayed in fewer copies, so
    this costs little more than 60 samples)."""
    from khepera_noise_ros.core.noise import NoiseModel
    config, recs = _emulated_robot_recordings(samples=EMULATED_LONG)
    sim = SimConfig(noise=NoiseModel.independent_only(config.sensor_noise))
    return config, diagnose.diagnose(recs, diagnose.Options(config=sim, replicates=100))


def test_on_the_emulated_robot_the_compound_beats_every_single_effect(emulated):
    """The simulator is the paper's independent model at the robot's own sensor noise;
    the robot has its default effects.  Every effect chosen is one the robot has, and
    the compound removes more of the held-out gap than any single effect."""
    config, result = emulated
    names = [c['name'] for c in result.to_json()['compound']['chosen']]
    assert len(names) >= 3 and set(names) <= set(config.enabled), names
    assert result.compound.reduction > max(e['heldout_reduction'] for e in result.effects)


def test_on_the_emulated_robot_the_turn_error_is_found_beside_the_sensor_effects(emulated):
    """Once flicker, latency and calibration are chosen the gap left is about 1% of the
    first; the turn error removes most of what is left of the closed-loop statistics'
    part (far less than 0.5% of the whole), and is chosen for that."""
    config, result = emulated
    chosen = {c['name']: c for c in result.to_json()['compound']['chosen']}
    assert {'intensity_dependent_noise', 'sensor_latency', 'sensor_gain_offset',
            'actuator_turn_error'} <= set(chosen), list(chosen)
    turn = chosen['actuator_turn_error']
    assert turn['added_reduction'] < 0.005 and turn['p_value'] < 0.05
    assert abs(turn['parameters']['scale'] - config.actuator_turn_error.scale) < 0.2


def test_on_the_emulated_robot_with_longer_runs_its_own_drift_is_fitted():
    """With 240 samples per heading, given the robot's flicker, calibration and latency
    (the oracle's: ``benchmark/emulated_set.py``), each sensor's own drift (0.4%, 50
    samples) shows in the part of its noise it does not share with the others
    (``gap.ownwander``): the drift's fitter finds it on every sensor, one wander each,
    near its size and time constant.  The flicker alone swamped it before."""
    config, recs = _emulated_robot_recordings(samples=EMULATED_LONG, episodes=2)
    import emulated_set as es           # on the path once the recordings are made
    fit_part, _ = es.parts(recs[:1], config)
    true = es.true_effects(config)
    names = ('sensor_gain_offset', 'intensity_dependent_noise', 'sensor_latency')
    given = fit_part.with_given([true[n] for n in names])
    cand = fit.drift(given, given.compare(replicates=40))
    assert cand.effect is not None, cand.note
    assert cand.effect.sensors == tuple(range(8)) and not cand.effect.shared, cand.note
    assert 0.5 < cand.effect.sd / config.temporal_drift.strength < 2.0, cand.effect
    assert 0.25 < cand.effect.time_constant / config.temporal_drift.time_constant < 4, \
        cand.effect


def test_on_the_emulated_robot_its_group_noise_is_found(emulated):
    """The robot's noise shared in three groups (0.3%): with the reading saturating once
    at the end (``test_gap_emulated2.py``) it is found, the groups (3, 4, 5) exactly and
    (0, 1, 2) together; before, one group of s3, s4 stood in for the flicker."""
    _, result = emulated
    chosen = {c['name']: c for c in result.to_json()['compound']['chosen']}
    assert 'correlated_noise' in chosen, list(chosen)
    groups = [sorted(g) for g in chosen['correlated_noise']['parameters']['groups']]
    assert [3, 4, 5] in groups, groups
    assert any({0, 1, 2} <= set(g) for g in groups), groups


def test_the_emulated_robots_default_effects_are_found_as_a_set(emulated):
    """All six, the drift (sd 0.4% of each sensor's gain, beside a flicker of up to 5%)
    too: its own-part autocorrelation (``gap.ownpart``) puts it in the discrepancy; it
    is a wander per sensor, near the robot's size."""
    config, result = emulated
    chosen = {c['name']: c for c in result.to_json()['compound']['chosen']}
    assert set(chosen) == set(config.enabled), list(chosen)
    drift = chosen['temporal_drift']['parameters']
    assert not drift['shared'] and 0.5 * 0.004 < drift['sd'] < 2 * 0.004, drift


def test_a_turn_error_small_beside_a_latency_is_still_found():
    """A latency makes almost all of the gap; the turn error left after it is a sliver of
    the gap before any effect but most of what the latency leaves of the closed-loop
    statistics: the selection keeps it, and stops there."""
    from test_gap_support import closed_loop_protocol
    hidden = [fx.SensorLatency(tuple(range(8)), 1), fx.ActuatorTurnError(0.85, 0.1)]
    recs = [recorded(stationary_protocol(samples=30), hidden, seed=5),
            recorded(closed_loop_protocol(24), hidden, seed=5)]
    result = diagnose.diagnose(recs, OPTIONS)
    chosen = result.to_json()['compound']['chosen']
    assert [c['name'] for c in chosen] == ['sensor_latency', 'actuator_turn_error'], chosen
    assert chosen[1]['added_reduction'] < 0.005
    assert abs(chosen[1]['parameters']['scale'] - 0.85) < 0.1


def test_a_turn_error_shows_in_recorded_headings_too():
    """A closed-loop recording that keeps its headings (a tracked robot): the turn size
    itself is a fingerprint, even where the readings' response to turns looks as
    simulated (their z are zeroed here), and the scale is taken from it."""
    import dataclasses as dc
    from khepera_noise_ros.gap import fit
    from test_gap_support import closed_loop_protocol
    rec = replay.replay(closed_loop_protocol(16), CONFIG, [fx.ActuatorTurnError(1.35, 0.0)],
                        seed=6)
    rec.manifest = dict(rec.manifest, source='hardware')
    target = Target([rec], CONFIG, 1, replicates=40)
    c = target.compare()
    quiet = np.array([0.0 if k.family in ('turn_response', 'sensor_turn_response') else z
                      for k, z in zip(c.keys, c.z)])
    assert any(k.family == 'turn_size' and abs(z) > 4 for k, z in zip(c.keys, c.z))
    cand = fit.actuator(target, dc.replace(c, z=quiet))
    assert cand.effect is not None, cand.note
    assert abs(cand.effect.scale - 1.35) < 0.15


def test_shared_noise_of_a_fixed_size_is_correlated_noise_in_every_group():
    """Two non-adjacent pairs share noise of 6 readings whatever the light (a supply):
    both groups are found and the fixed size is fitted."""
    hidden = [fx.CorrelatedNoise(((3, 5), (0, 6)), 0.0, 6.0)]
    result = diagnose.diagnose([recorded(stationary_protocol(samples=30), hidden, seed=5)],
                               OPTIONS)
    assert result.top_effect == 'correlated_noise', result.effects[:2]
    p = result.effects[0]['parameters']
    assert sorted(map(sorted, p['groups'])) == [[0, 6], [3, 5]]
    assert abs(p['constant'] - 6.0) < 1.5 and p['strength'] < 0.005
