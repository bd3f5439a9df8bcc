"""The diagnosis's side of the world model: the turn statistics per command and after lone
turns, the turn calibration's replay and its turns (measured, or inferred through a
sweep), and the world identified before the noise effects."""
from __future__ import annotations

import numpy as np
import pytest

from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.effects import (ActuatorResponse, ActuatorTurnError, LightResponse,
                                       SensorResponse, WORLD_MODEL)
from khepera_noise_ros.effects.base import Candidate
from khepera_noise_ros.gap import diagnose, turns
from khepera_noise_ros.gap.protocol import kind
from khepera_noise_ros.gap.replay import Replayer
from khepera_noise_ros.gap.target import Target
from khepera_noise_ros.recording import FORMAT, Recording
from khepera_noise_ros.testing import protocols
from khepera_noise_ros.testing.protocols import turn_calibration
from khepera_noise_ros import simconfig

CONFIG = simconfig.SimConfig(noise=NoiseModel.independent_only(0.02))
TASK = {'lamp_distance_mm': 5.0, 'ambient': 500.0}
GENOME = [0.9, -0.6, 0.5, -0.4, 0.7, 0.3, -0.8, 0.9, -0.5, 0.6, -0.9, -0.2, 2.5, -1.5, -2.5,
          1.5, 0.1, -0.1, 0.2, 0.3]
ACTUATOR = ActuatorResponse(3.0, 0.9, 0.25)


def manifest(protocol: str, conditions: dict, **extra) -> dict:
    return {'format': FORMAT, 'source': 'simulator', 'sample_period_s': 1.0,
            'protocol': protocol, 'conditions': conditions, **extra}


def recording(rows: list, protocol: str, conditions: dict, **extra) -> Recording:
    e, s, h, c, d, p = (np.array(v) for v in zip(*rows))
    n = len(rows)
    return Recording(e, s, h.astype(float), c, np.zeros((n, 8)), d.astype(float),
                     p.astype(float), manifest(protocol, conditions, **extra))


def sweep(step: float = 10.0, samples: int = 10) -> Recording:
    """The record command's sweep in the task's light: a placement per heading."""
    heads = np.arange(-180.0, 180.0, step)
    return recording([(k, t, h, 'bulb_1ft', np.nan, np.nan) for k, h in enumerate(heads)
                      for t in range(samples)], 'stationary', {'bulb_1ft': TASK})


def closed_loop(episodes: int = 16) -> Recording:
    return recording([(e, t, np.nan, 'task', 1, 1) for e in range(episodes)
                      for t in range(60)], 'closed_loop', {'task': TASK}, genome=GENOME)


def recorded(protocol: Recording, effects=(), seed: int = 5, tracked: bool = True
             ) -> Recording:
    rec = Replayer(protocol, CONFIG).replay(tuple(effects), seed)
    rec.manifest = dict(protocol.manifest, source='emulator')
    if not tracked and kind(rec) == 'closed_loop':
        rec.heading_deg = protocol.heading_deg.copy()
    return rec


def statistics(rec: Recording) -> dict:
    real = Target([rec], CONFIG, 0, replicates=20).real
    return {k: v for k, v in zip(real.keys, real.estimate)}


def test_the_calibration_replays_its_commands_from_its_placements():
    rec = recorded(turn_calibration(repeats=1))
    first = rec.step == 0
    np.testing.assert_array_equal(rec.heading_deg[first], -1.5 * np.arange(1, 10))
    turned = np.flatnonzero(rec.power > 0)
    made = (rec.heading_deg[turned + 1] - rec.heading_deg[turned] + 180) % 360 - 180
    np.testing.assert_allclose(made, 3.0 * rec.direction[turned] * rec.power[turned])
    assert len(turned) == 36 and rec.power[~np.isin(np.arange(len(rec)), turned)].max() == 0


def test_the_turn_per_command_and_the_settling_are_compared_where_they_can_be():
    tracked = statistics(recorded(turn_calibration(), [ACTUATOR]))
    turn = {k.part: v for k, v in tracked.items() if k.family == 'turn_by_command'}
    assert len(turn) == 18
    assert turn['right 9'] == pytest.approx(0.9 * 1.25 * 24.0, abs=0.3)
    assert turn['left 9'] == pytest.approx(-0.9 * 0.75 * 24.0, abs=0.3)
    assert turn['right 1'] == 0.0                  # a turn inside the dead-band
    assert any(k.family == 'turn_step_response' for k in tracked)
    untracked = statistics(recorded(turn_calibration(), [ACTUATOR], tracked=False))
    assert not any(k.family == 'turn_by_command' for k in untracked)
    assert sum(k.family == 'turn_imbalance' for k in untracked) == 18


def test_turns_are_measured_where_headings_are_known_and_inferred_through_a_sweep():
    loop = recorded(turn_calibration(), [ACTUATOR], tracked=False)
    assert turns.measured([loop], [], CONFIG).shape == (0, 2)     # nothing to infer with
    made = turns.measured([loop], [recorded(sweep())], CONFIG)
    assert made.shape == (108, 2)
    error = np.abs(made[:, 1] - ACTUATOR.mean(made[:, 0]))
    assert error.mean() < 0.6 and error.max() < 3.0, error
    tracked = turns.measured([recorded(turn_calibration(), [ACTUATOR])], [], CONFIG)
    np.testing.assert_allclose(tracked[:, 1], ACTUATOR.mean(tracked[:, 0]), atol=0.2)


def test_the_diagnosis_identifies_the_world_before_the_noise():
    knots = tuple(float(b) for b in np.arange(-180.0, 180.0, 10.0))
    d = np.abs((np.array(knots) + 180.0) % 360.0 - 180.0)
    light = LightResponse((2, 3), knots, (5.0,), (500.0,), tuple(np.round(np.r_[
        500 - 420 * np.exp(-np.log(2) * (np.abs(d - 10) / 20) ** 2),
        500 - 420 * np.exp(-np.log(2) * (np.abs(d + 10) / 20) ** 2)], 2)))
    truth = [light, SensorResponse(tuple(range(8)), 0.0, 0.5, 0.5), ACTUATOR]
    recordings = [recorded(sweep(), truth, seed=1), recorded(turn_calibration(), truth, seed=2),
                  recorded(closed_loop(), truth, seed=3)]
    result = diagnose.diagnose(recordings, diagnose.Options(
        config=CONFIG, replicates=60, remainder=False, rounding=False))
    assert result.world is not None, result.notes
    found = [e.name for e in result.world.effects]
    assert {'light_response', 'actuator_response'} <= set(found), result.world.notes
    block = result.to_json()['world']
    assert block['heldout_reduction'] > 0.5 and block['p_value'] < 0.05
    assert [e.name for e in result.fitted_effects][:len(found)] == found
    assert not set(WORLD_MODEL) & {e['name'] for e in result.effects}
    actuator = next(e for e in result.world.effects if e.name == 'actuator_response')
    assert actuator.dead_band == pytest.approx(3.0, abs=0.6)


def test_a_world_part_gives_way_to_its_plain_case_where_the_held_out_data_prefer_it(
        monkeypatch):
    """A robot that turns 0.6 of each command, and a turn fit that took a dead-band (as a
    robot's other effects can lead it to): the part brings the simulator closer than the
    stock, its plain case closer still, so the plain case is named and the world stays
    the simulator's; a part closer than its plain case stays (the test above)."""
    misfit = ActuatorResponse(dead_band=2.0, gain=0.7)
    monkeypatch.setattr(ActuatorResponse, 'fit', classmethod(
        lambda cls, evidence: Candidate(cls.name, misfit, 'a dead-band of 2 deg')))
    truth = [ActuatorTurnError(0.6)]
    recordings = [recorded(closed_loop(), truth, seed=3), recorded(closed_loop(), truth, seed=4)]
    result = diagnose.diagnose(recordings, diagnose.Options(
        config=CONFIG, replicates=40, remainder=False, rounding=False))
    note = next(n for n in result.notes if n.startswith("the world model is the simulator's"))
    assert result.world is None and 'left to actuator_turn_error' in note, result.notes
    assert [e.name for e in result.named_effects] == ['actuator_turn_error']
    assert result.named_effects[0].scale == pytest.approx(0.6, abs=0.05)


def test_a_world_part_the_held_out_data_are_closer_without_is_dropped(monkeypatch):
    """A robot with the task's light shape and a dead-band but sensors as quick as
    simulated, and a sensor fit that took a slow response (as a robot's other effects can
    lead it to): with it the held-out data are farther than without it, so it is dropped
    and the notes say so; the parts the robot has stay."""
    knots = tuple(float(b) for b in np.arange(-180.0, 180.0, 10.0))
    d = np.abs((np.array(knots) + 180.0) % 360.0 - 180.0)
    light = LightResponse((2, 3), knots, (5.0,), (500.0,), tuple(np.round(np.r_[
        500 - 420 * np.exp(-np.log(2) * (np.abs(d - 10) / 20) ** 2),
        500 - 420 * np.exp(-np.log(2) * (np.abs(d + 10) / 20) ** 2)], 2)))
    slow = SensorResponse(tuple(range(8)), 0.0, 0.2, 0.2)
    monkeypatch.setattr(SensorResponse, 'fit', classmethod(
        lambda cls, evidence: Candidate(cls.name, slow, 'a slow response')))
    truth = [light, ACTUATOR]
    recordings = [recorded(sweep(), truth, seed=1), recorded(turn_calibration(), truth, seed=2),
                  recorded(closed_loop(), truth, seed=3)]
    result = diagnose.diagnose(recordings, diagnose.Options(
        config=CONFIG, replicates=60, remainder=False, rounding=False, effects=WORLD_MODEL))
    assert result.world is not None, result.notes
    assert [e.name for e in result.world.effects] == ['light_response', 'actuator_response']
    assert 'dropped: the held-out data are closer without it' in \
        result.world.notes['sensor_response'], result.world.notes


def test_without_the_protocols_the_world_is_the_simulator_s_and_the_notes_say_which():
    """Section 2's kind of recording (a few headings, no turns) of a robot with a
    misshapen light response: no part is identified, and the notes name the protocols
    that would (the sweep for the shape, the turn calibration for the wheels)."""
    knots = tuple(float(b) for b in np.arange(-180.0, 180.0, 10.0))
    d = np.abs((np.array(knots) - 45.0 + 180.0) % 360.0 - 180.0)
    narrow = LightResponse((1,), knots, (5.0,), (500.0,), tuple(np.round(
        500.0 - 430.0 * np.exp(-np.log(2) * (d / 25.0) ** 2), 2)))
    rec = protocols.recorded(protocols.sweep(step=90.0, samples=30), [narrow], seed=5)
    result = diagnose.diagnose([rec], diagnose.Options(config=CONFIG, replicates=40))
    assert result.gap_significant and result.world is None
    note = next(n for n in result.notes if n.startswith("the world model is the simulator's"))
    assert 'record --protocol sweep' in note and 'record --protocol turns' in note, note
