"""A random turn slip (no scale error) found from closed-loop recordings.

The 'robot' is the simulator with a hidden ``actuator_turn_error``
(``test_gap_support.recorded``); the diagnosis sees only the recording.  A slip as
often left as right leaves the turn responses' means and slopes alone: only the
scatter statistics (``gap.turnscatter``) can show it.
"""
import numpy as np
import pytest

from khepera_noise_ros.gap import diagnose, fitturn, replay, turnscatter
from khepera_noise_ros.gap import effects as fx
from khepera_noise_ros.gap.target import Target
from test_gap_support import CONFIG, closed_loop_protocol, recorded, stationary_protocol

OPTIONS = diagnose.Options(config=CONFIG, replicates=40)
SLIP = 0.3                # sd of the slip per degree turned
SLIP_TOLERANCE = 0.08


def _closed_loop(effects, headings: bool, seed: int = 6):
    rec = recorded(closed_loop_protocol(16), effects, seed=seed)
    if headings:              # a tracked robot: the headings the replay had
        rec.heading_deg[:] = replay.replay(closed_loop_protocol(16), CONFIG, effects,
                                           seed=seed).heading_deg
    return rec


@pytest.mark.parametrize('headings', [True, False], ids=['headings', 'no_headings'])
def test_a_random_slip_with_no_scale_error_is_found_and_sized(headings):
    rec = _closed_loop([fx.ActuatorTurnError(1.0, SLIP)], headings)
    assert np.isfinite(rec.heading_deg).all() == headings
    result = diagnose.diagnose([rec], OPTIONS)
    assert result.gap_significant
    assert result.top_effect == 'actuator_turn_error', result.effects[:2]
    top = result.effects[0]
    assert top['parameters']['slip'] == pytest.approx(SLIP, abs=SLIP_TOLERANCE)
    assert top['parameters']['scale'] == pytest.approx(1.0, abs=0.1)
    assert top['heldout_reduction'] > 0.5


def test_the_slip_shows_in_the_scatter_not_in_the_slopes():
    rec = _closed_loop([fx.ActuatorTurnError(1.0, SLIP)], True)
    c = Target([rec], CONFIG, 1, replicates=40).compare()
    z = {f: max((abs(v) for k, v in zip(c.keys, c.z) if k.family == f), default=0.0)
         for f in fitturn.FAMILIES}
    assert z['turn_size_scatter'] > 10 and z['turn_scatter'] > 4, z
    assert z['turn_size'] < 4, z


def test_a_scale_error_alone_is_still_found_with_its_scale():
    rec = _closed_loop([fx.ActuatorTurnError(1.35, 0.0)], False)
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
    hidden = [fx.SensorGainOffset((2,), (1.15,), (-10.0,)), fx.ActuatorTurnError(1.0, SLIP)]
    recs = [recorded(stationary_protocol(samples=20), hidden[:1], seed=5),
            _closed_loop(hidden, False)]
    result = diagnose.diagnose(recs, OPTIONS)
    chosen = result.to_json()['compound']['chosen']
    assert {c['name'] for c in chosen} == {'sensor_gain_offset', 'actuator_turn_error'}, chosen
    turn = next(c for c in chosen if c['name'] == 'actuator_turn_error')
    assert turn['parameters']['slip'] == pytest.approx(SLIP, abs=SLIP_TOLERANCE)


def test_a_creep_at_power_0_is_its_own_parameter():
    """A creep turns the robot when no turn is commanded; its draws come after the
    slip's, so effects without it replay as before."""
    rng = np.random.default_rng(0)
    turn = fx.ActuatorTurnError(1.0, 0.0, creep=2.0).process(1, 8, rng)
    still = np.array([turn(np.zeros(1))[0] for _ in range(2000)])
    assert np.std(still) == pytest.approx(2.0, rel=0.1)
    plain = fx.ActuatorTurnError(1.0, 0.2).process(1, 8, np.random.default_rng(1))
    old = fx.ActuatorTurnError(1.0, 0.2, creep=0.0).process(1, 8, np.random.default_rng(1))
    assert plain(np.array([10.0]))[0] == old(np.array([10.0]))[0]
    back = fx.from_dict(fx.to_dict(fx.ActuatorTurnError(0.9, 0.1, creep=1.5)))
    assert back.creep == 1.5
    assert fx.from_dict({'name': 'actuator_turn_error', 'scale': 0.9, 'slip': 0.1}).creep == 0
    with pytest.raises(ValueError, match='creep >= 0'):
        fx.from_dict({'name': 'actuator_turn_error', 'creep': -1.0})


def test_scatter_by_band_measures_a_known_heading_scatter():
    """With headings, the power band's rms about the pooled turn per unit of command is
    the slip's sd in degrees (3 deg per unit of power)."""
    rec = replay.replay(closed_loop_protocol(16), CONFIG, [fx.ActuatorTurnError(1.0, SLIP)],
                        seed=3)
    u = rec.direction * rec.power
    h = np.zeros((len(turnscatter.BANDS), 4))
    for e in np.unique(rec.episode):
        i = rec.episode == e
        h += turnscatter.heading_moments(rec.heading_deg[i], u[i], rec.step[i],
                                         CONFIG.task.perturb_every)
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
    rec = replay.replay(protocol, CONFIG, [fx.ActuatorTurnError(1.0, 0.0, creep=2.0)], seed=6)
    rec.manifest = dict(protocol.manifest, source='emulator')
    if not headings:
        rec.heading_deg[:] = np.nan
    result = diagnose.diagnose([rec], OPTIONS)
    assert result.top_effect == 'actuator_turn_error', result.effects[:2]
    p = result.effects[0]['parameters']
    if headings:              # the turn itself is measured: the creep is sized
        assert p['creep'] == pytest.approx(2.0, abs=0.4)
        assert p['slip'] < 0.1 and p['scale'] == pytest.approx(1.0, abs=0.1)
    else:
        assert p['creep'] > 0.5
