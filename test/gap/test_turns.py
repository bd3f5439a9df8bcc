"""The actuator's turn error in closed-loop recordings: a scale error, a random slip and a
creep at power 0, alone and beside a latency or a sensor effect.

The 'robot' is the closed-loop simulator with hidden effects (headings unknown, as on a
real robot, or kept, as from a tracked one), or the emulated robot; the diagnosis sees
only the recording.  A slip as often left as right leaves the turn responses' means and
slopes alone: only the scatter statistics can show it.
"""
import dataclasses

import numpy as np
import pytest

from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.effects import ActuatorTurnError, SensorGainOffset, SensorLatency
from khepera_noise_ros.effects import actuator_turn_error
from khepera_noise_ros.gap import closedloop, diagnose
from khepera_noise_ros.gap.compare import Comparison
from khepera_noise_ros.simconfig import SimConfig
from khepera_noise_ros.gap.target import Target
from khepera_noise_ros.reality.effects import EffectsConfig
from khepera_noise_ros.testing import emulated
from khepera_noise_ros.testing.protocols import (CONFIG, closed_loop_protocol, recorded,
                                                 stationary_protocol, tracked)

OPTIONS = diagnose.Options(config=CONFIG, replicates=40)
SLIP = 0.3                # sd of the slip per degree turned
SLIP_TOLERANCE = 0.08


def _closed_loop(effects, headings: bool, seed: int = 6):
    protocol = closed_loop_protocol(16)
    return (tracked if headings else recorded)(protocol, effects, seed=seed)


@pytest.mark.parametrize('headings', [True, False], ids=['headings', 'no_headings'])
def test_a_random_slip_with_no_scale_error_is_found_and_sized(headings):
    rec = _closed_loop([ActuatorTurnError(1.0, SLIP)], headings)
    assert np.isfinite(rec.heading_deg).all() == headings
    result = diagnose.diagnose([rec], OPTIONS)
    assert result.gap_significant
    assert result.top_effect == 'actuator_turn_error', result.effects[:2]
    top = result.effects[0]
    assert top['parameters']['slip'] == pytest.approx(SLIP, abs=SLIP_TOLERANCE)
    assert top['parameters']['scale'] == pytest.approx(1.0, abs=0.1)
    assert top['heldout_reduction'] > 0.5


def test_the_slip_shows_in_the_scatter_not_in_the_slopes():
    rec = _closed_loop([ActuatorTurnError(1.0, SLIP)], True)
    c = Target([rec], CONFIG, 1, replicates=40).compare()
    z = {f: max((abs(v) for k, v in zip(c.keys, c.z) if k.family == f), default=0.0)
         for f in actuator_turn_error.FAMILIES}
    assert z['turn_size_scatter'] > 10 and z['turn_scatter'] > 4, z
    assert z['turn_size'] < 4, z


def test_a_scale_error_alone_is_still_found_with_its_scale():
    rec = _closed_loop([ActuatorTurnError(1.35, 0.0)], False)
    result = diagnose.diagnose([rec], OPTIONS)
    assert result.top_effect == 'actuator_turn_error', result.effects[:2]
    p = result.effects[0]['parameters']
    assert p['scale'] == pytest.approx(1.35, abs=0.1)
    assert p['slip'] < 0.1


@pytest.mark.parametrize('headings', [True, False], ids=['headings', 'no_headings'])
def test_a_clean_closed_loop_is_answered_none(headings):
    """The scatter is compared (and found as simulated), and no turn error is named."""
    result = diagnose.diagnose([_closed_loop([], headings, seed=7)], OPTIONS)
    assert result.top_effect == 'none', result.effects[:2]
    c = result.held_out_before
    scatter = [(k.family, p) for k, p in zip(c.keys, c.p_holm) if k.family.endswith('scatter')]
    assert {f for f, _ in scatter} == (
        {'turn_scatter', 'turn_size_scatter'} if headings else {'turn_scatter'})
    assert all(p >= 0.01 for _, p in scatter), scatter


def test_a_slip_and_a_sensor_effect_are_kept_together():
    """Stationary and closed-loop recordings of a robot whose sensor s2 reads with a gain
    error and whose wheels slip: the slip's discrepancy lies in the closed loop alone,
    beside a larger stationary one, and the compound keeps both."""
    hidden = [SensorGainOffset((2,), (1.15,), (-10.0,)), ActuatorTurnError(1.0, SLIP)]
    recs = [recorded(stationary_protocol(samples=20), hidden[:1], seed=5),
            _closed_loop(hidden, False)]
    result = diagnose.diagnose(recs, OPTIONS)
    chosen = result.to_json()['compound']['chosen']
    assert {c['name'] for c in chosen} == {'sensor_gain_offset', 'actuator_turn_error'}, chosen
    turn = next(c for c in chosen if c['name'] == 'actuator_turn_error')
    assert turn['parameters']['slip'] == pytest.approx(SLIP, abs=SLIP_TOLERANCE)


def test_scatter_by_band_measures_a_known_heading_scatter():
    """With headings, the power band's rms about the pooled turn per unit of command is
    the slip's sd in degrees (3 deg per unit of power)."""
    rec = tracked(closed_loop_protocol(16), [ActuatorTurnError(1.0, SLIP)], seed=3)
    b = closedloop.blocks(rec, rec.readings, lambda order, ep, m: {},
                          CONFIG.task.perturb_every)
    h = b.part(b.sums, 'heading_band').sum(axis=0)       # per band: n, u^2, u dh, dh^2
    assert h.shape == (len(closedloop.POWER_BANDS), 4)
    band = h[2]                                     # power 6-9
    k = h[:, 2].sum() / h[:, 1].sum()
    rms = np.sqrt((band[3] - 2 * k * band[2] + k * k * band[1]) / band[0])
    expected = SLIP * CONFIG.world.deg_per_power * np.sqrt(band[1] / band[0])
    assert rms == pytest.approx(expected, rel=0.15)


# a controller that often stands still (power 0 in about 45% of steps, else 1-3)
STILL_GENOME = [-2.3, -1.5, 1.8, -0.3, 2.3, 0.6, 1.7, -1.9, -1.1, -0.7, 0.0, -0.2, 1.9, -2.0,
                2.1, 2.3, -2.5, -2.9, -1.2, -0.6]


@pytest.mark.parametrize('headings', [True, False], ids=['headings', 'no_headings'])
def test_a_creep_at_power_0_is_found(headings):
    protocol = closed_loop_protocol(16)
    protocol.manifest = dict(protocol.manifest, genome=STILL_GENOME)
    effects = [ActuatorTurnError(1.0, 0.0, creep=2.0)]
    rec = (tracked if headings else recorded)(protocol, effects, seed=6)
    result = diagnose.diagnose([rec], OPTIONS)
    assert result.top_effect == 'actuator_turn_error', result.effects[:2]
    p = result.effects[0]['parameters']
    if headings:              # the turn itself is measured: the creep is sized
        assert p['creep'] == pytest.approx(2.0, abs=0.4)
        assert p['slip'] < 0.1 and p['scale'] == pytest.approx(1.0, abs=0.1)
    else:
        assert p['creep'] > 0.5


def test_a_turn_error_shows_in_recorded_headings_too():
    """A closed-loop recording that keeps its headings (a tracked robot): the turn size
    itself is a fingerprint, even where the readings' response to turns looks as
    simulated (their z are zeroed here), and the scale is taken from it."""
    rec = tracked(closed_loop_protocol(16), [ActuatorTurnError(1.35, 0.0)], seed=6)
    rec.manifest = dict(rec.manifest, source='hardware')
    target = Target([rec], CONFIG, 1, replicates=40)
    c = target.compare()
    quiet = np.array([0.0 if k.family in ('turn_response', 'sensor_turn_response') else z
                      for k, z in zip(c.keys, c.z)])
    assert any(k.family == 'turn_size' and abs(z) > 4 for k, z in zip(c.keys, c.z))
    cand = ActuatorTurnError.fit(target.evidence(Comparison(c.keys, c.real, c.sim, c.se,
                                                            quiet)))
    assert cand.effect is not None, cand.note
    assert abs(cand.effect.scale - 1.35) < 0.15


# -- beside a latency -------------------------------------------------------------------

def test_a_turn_error_small_beside_a_latency_is_still_found():
    """A latency makes almost all of the gap; the turn error left after it is a sliver of
    the gap before any effect but most of what the latency leaves of the closed-loop
    statistics: the selection keeps it, and stops there."""
    hidden = [SensorLatency(tuple(range(8)), 1), ActuatorTurnError(0.85, 0.1)]
    recs = [recorded(stationary_protocol(samples=30), hidden, seed=5),
            recorded(closed_loop_protocol(24), hidden, seed=5)]
    result = diagnose.diagnose(recs, diagnose.Options(config=CONFIG, replicates=60))
    chosen = result.to_json()['compound']['chosen']
    assert [c['name'] for c in chosen] == ['sensor_latency', 'actuator_turn_error'], chosen
    assert chosen[1]['added_reduction'] < 0.005
    assert abs(chosen[1]['parameters']['scale'] - 0.85) < 0.1


def test_a_turn_error_beside_a_latency_that_took_its_share():
    """A latency of three steps on two sensors, turns 1.35 times the commanded and a
    small calibration error on a third sensor (case 21 of ``blind_compound.py --hard
    --seed 0``), on the emulated robot with the lamp's bearing kept.  The latency,
    fitted alone first, takes part of the turn error's share (its sensor set bends to
    the turns); given it the turn error fitted the wrong way (scale 0.87) and made the
    closed loop worse, and a spread law came in instead (held-out shrink 0.65).  Fitted
    without the latency, the latency then refitted given it, the pair is found."""
    config = EffectsConfig.none(0.02).only(
        'sensor_latency', 'actuator_turn_error', 'sensor_gain_offset',
        sensor_latency={'strength': 3, 'location': (0, 1)},
        actuator_turn_error={'scale': 1.3472112889087093, 'strength': 0.18200775202216513},
        sensor_gain_offset={'gains': (1, 1, 0.9579582001682678, 1, 1, 1, 1, 1),
                            'offsets': (0, 0, -2.465462814917963, 0, 0, 0, 0, 0),
                            'location': (2,)})
    seed = 1455561792
    recording = emulated.record_closed_loop(emulated.robot(config, seed),
                                            emulated.evolved_genome(0), seed=seed,
                                            headings=True)
    options = diagnose.Options(config=SimConfig(noise=NoiseModel.independent_only(0.02)),
                               remainder=False)
    result = diagnose.diagnose([recording], dataclasses.replace(options, seed=21)).to_json()
    chosen = result['compound']['chosen']
    names = [c['name'] for c in chosen]
    assert {'sensor_latency', 'actuator_turn_error'} <= set(names), chosen
    assert 'intensity_dependent_noise' not in names, chosen
    turn = next(c for c in chosen if c['name'] == 'actuator_turn_error')
    assert 1.2 < turn['parameters']['scale'] < 1.5, turn
    assert result['compound']['heldout_reduction'] > 0.9
