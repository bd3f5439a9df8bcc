"""The world model's effects (light_response, sensor_response, actuator_response): their
contract (declared parameters, dict and params-file round trips, one simulation step by
step and over a whole run), where they act in the simulator, and each fitter recovering
its own effect from a recording simulated with it.  The recordings are the record
command's protocols (a heading sweep, a turn calibration), made by the simulator's
replay; the fitters see them only against the plain simulator."""
from __future__ import annotations

import numpy as np
import pytest

from khepera_noise_ros import effects as fx
from khepera_noise_ros.core.khepera import TENTHS, World
from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.core.task import Task
from khepera_noise_ros.effects import (ActuatorResponse, ActuatorTurnError, LightResponse,
                                       SensorResponse, Stage)
from khepera_noise_ros.effects.simulate import EffectEpisodes, light_table
from khepera_noise_ros.gap.protocol import kind
from khepera_noise_ros.gap.replay import Replayer
from khepera_noise_ros.gap.target import Target
from khepera_noise_ros.recording import Recording
from khepera_noise_ros.testing.protocols import sweep, turn_calibration
from khepera_noise_ros import simconfig

CONFIG = simconfig.SimConfig(noise=NoiseModel.independent_only(0.02))
KNOTS = tuple(float(b) for b in np.arange(-180.0, 180.0, 10.0))


def recorded(protocol: Recording, effects=(), seed: int = 5, tracked: bool = True
             ) -> Recording:
    """The protocol recorded from a robot with ``effects``; untracked: headings known only
    where the experimenter placed the robot."""
    rec = Replayer(protocol, CONFIG).replay(tuple(effects), seed)
    rec.manifest = dict(protocol.manifest, source='emulator')
    if not tracked and kind(rec) == 'closed_loop':
        rec.heading_deg = np.where(np.isfinite(protocol.heading_deg), protocol.heading_deg,
                                   np.nan)
    return rec


def fitted(cls, recordings):
    target = Target(recordings, CONFIG, 1, replicates=60)
    return cls.fit(target.evidence(target.compare(replicates=40)))


def lobe(axis: float, width: float) -> np.ndarray:
    """A narrower lobe than the simulator's, at the knots."""
    d = np.abs((np.array(KNOTS) - axis + 180.0) % 360.0 - 180.0)
    return 500.0 - 430.0 * np.exp(-np.log(2) * (d / width) ** 2)


NARROW = LightResponse((1, 2), KNOTS, (5.0,), (500.0,),
                       tuple(np.round(np.r_[lobe(45.0, 25.0), lobe(10.0, 20.0)], 2)))
EXAMPLES = [NARROW, LightResponse((4,), (0.0, 90.0), (5.0, 130.0), (500.0, 500.0),
                                  (100.0, 480.0, 300.0, 490.0), 'model'),
            SensorResponse((0, 1, 2), 0.6, 0.3, 0.5), SensorResponse((3,), 1.4),
            ActuatorResponse(3.0, 0.9, 0.2, (3.0, 9.0, 27.0), (0.5, 1.0, 1.1), 0.1, 0.5),
            ActuatorResponse(1.0, 1.1, -0.1, knocks=False)]


@pytest.mark.parametrize('example', EXAMPLES, ids=lambda e: e.name)
def test_round_trips_keep_the_effect(example, tmp_path):
    assert fx.from_dict(example.to_dict()) == example
    assert fx.loads(fx.dumps([example])) == (example,)
    path = simconfig.write(CONFIG.with_effects(example), tmp_path / 'p.yaml')
    assert simconfig.load(path).effects == (example,)


@pytest.mark.parametrize('example', EXAMPLES, ids=lambda e: e.name)
@pytest.mark.parametrize('held', [False, True])
def test_step_by_step_and_over_a_run_give_the_same_numbers(example, held):
    rng = np.random.default_rng(3)
    turns = example.stage is Stage.ACTUATOR
    level = rng.uniform(-30, 30, (40, 1, 3)) if turns else rng.uniform(20, 520, (40, 8, 3))
    if held:
        level = np.repeat(level[::10], 10, axis=0)
    kept = level.copy()
    step = example.start(3, level.shape[1], np.random.default_rng(7))
    stepwise = np.stack([step(level[t, 0]) if turns else step(level[t])
                         for t in range(40)])
    whole = example.over_time(level, np.random.default_rng(7))
    np.testing.assert_allclose(stepwise.reshape(whole.shape), whole, rtol=1e-10, atol=1e-9)
    np.testing.assert_array_equal(level, kept)


@pytest.mark.parametrize('cls, fields, bad', [
    (LightResponse, dict(sensors=(1,), bearings=(0.0, 90.0), lamps=(5.0,), ambients=(500.0,),
                         levels=(1.0, 2.0, 3.0)), 'levels'),
    (LightResponse, dict(sensors=(1,), bearings=(-180.0, 180.0), lamps=(5.0,),
                         ambients=(500.0,), levels=(1.0, 2.0)), 'bearings'),
    (SensorResponse, dict(sensors=(1,), rate_bright=0.0), 'rate_bright'),
    (SensorResponse, dict(sensors=(1,), delay=-1.0), 'delay'),
    (ActuatorResponse, dict(sizes=(3.0, 9.0), scales=(1.0,)), 'scale'),
    (ActuatorResponse, dict(asymmetry=1.5), 'asymmetry')])
def test_bad_values_are_refused_in_one_line_naming_them(cls, fields, bad):
    with pytest.raises(ValueError, match=bad) as info:
        cls(**fields)
    assert '\n' not in str(info.value)


def test_the_light_table_is_the_robot_s_where_named_and_the_world_s_elsewhere():
    world = World()
    table, own = light_table(world, [NARROW]), light_table(world)
    at = np.rint(np.mod(KNOTS, 360.0) * 10).astype(int) % TENTHS
    np.testing.assert_allclose(table[1, at], lobe(45.0, 25.0), atol=0.01)
    np.testing.assert_allclose(table[2, at], lobe(10.0, 20.0), atol=0.01)
    np.testing.assert_array_equal(np.delete(table, [1, 2], axis=0), np.delete(own, [1, 2], 0))
    other = World(lamp_distance_mm=130.0)         # a condition the table does not list
    np.testing.assert_array_equal(light_table(other, [NARROW]), light_table(other))
    # the closed loop reads the table: a robot held at bearing 45 sees s1's tabled peak
    noiseless = NoiseModel.independent_only(0.0)
    env = EffectEpisodes(world, noiseless, Task(steps=3, perturbation_deg=0.0), [NARROW])
    for bearing in (45.0, 100.0, -30.0):
        readings = env.reset([1], bearing_deg=bearing)
        at = int(round(bearing * 10)) % TENTHS
        np.testing.assert_array_equal(readings[0], np.rint(table[:, at]))


def test_knocks_go_through_the_wheels_when_asked():
    """A dead-band wider than every knock leaves the heading where it was; without knocks
    through the wheels the same robot is knocked about."""
    noiseless = NoiseModel.independent_only(0.0)
    task = Task(steps=30, perturb_every=5, perturbation_deg=25.0)
    for knocks, still in ((True, True), (False, False)):
        env = EffectEpisodes(World(), noiseless, task, [ActuatorResponse(30.0, knocks=knocks)])
        env.reset(np.arange(4))
        headings = []
        while not env.done:
            headings.append(env.bearing_deg.copy())
            env.step(np.ones(4, int), np.zeros(4, int))
        assert (np.ptp(headings, axis=0) == 0).all() == still


def test_light_response_is_found_on_the_sensors_it_names_and_tabled():
    cand = fitted(LightResponse, [recorded(sweep(step=10.0), [NARROW])])
    effect = cand.effect
    assert isinstance(effect, LightResponse), cand.note
    assert {1, 2} <= set(effect.sensors) and 'task: -180, -170' in cand.note
    table, truth = light_table(World(), [effect]), light_table(World(), [NARROW])
    assert np.abs(table[1:3] - truth[1:3]).mean() < 3.0       # readings, of 50 .. 500
    assert np.abs(table[1:3] - truth[1:3]).max() < 25.0


def test_sensor_response_recovers_a_lag_from_step_responses():
    truth = SensorResponse(tuple(range(8)), 0.0, 0.4, 0.4)
    cand = fitted(SensorResponse, [recorded(sweep(step=45.0, within=True), [truth])])
    effect = cand.effect
    assert isinstance(effect, SensorResponse), cand.note
    assert effect.sensors == truth.sensors
    assert effect.delay == pytest.approx(0.0, abs=0.15)
    assert effect.rate_bright == pytest.approx(0.4, abs=0.1)


def test_sensor_response_recovers_a_delay_and_two_rates_from_the_turn_calibration():
    truth = SensorResponse(tuple(range(8)), 0.3, 0.5, 0.8)
    cand = fitted(SensorResponse, [recorded(turn_calibration(), [truth])])
    effect = cand.effect
    assert isinstance(effect, SensorResponse), cand.note
    assert effect.sensors == truth.sensors and 'after turns' in cand.note
    assert effect.delay == pytest.approx(0.3, abs=0.15)
    assert (effect.rate_bright, effect.rate_dark) == pytest.approx((0.5, 0.8), abs=0.12)


def test_a_whole_step_delay_is_left_to_sensor_latency():
    cand = fitted(SensorResponse, [recorded(sweep(step=45.0, within=True),
                                            [SensorResponse((0, 1, 2, 3), 1.0)])])
    assert cand.effect is None and "sensor_latency's case" in cand.note


ACTUATOR = ActuatorResponse(3.0, 0.9, 0.25, scatter=0.05, jitter=0.3)


@pytest.mark.parametrize('tracked', [True, False])
def test_actuator_response_recovers_dead_band_gain_and_sides_from_the_calibration(tracked):
    """Tracked: the turns are the headings' changes; untracked: each end of a turn is
    inferred from its readings through a heading sweep of the same condition."""
    recordings = [recorded(turn_calibration(), [ACTUATOR], tracked=tracked)]
    if not tracked:
        recordings.append(recorded(sweep(step=10.0, samples=10)))
    cand = fitted(ActuatorResponse, recordings)
    effect = cand.effect
    assert isinstance(effect, ActuatorResponse), cand.note
    assert effect.dead_band == pytest.approx(3.0, abs=0.5)
    assert effect.gain == pytest.approx(0.9, abs=0.05)
    assert effect.asymmetry == pytest.approx(0.25, abs=0.05)
    assert effect.scatter == pytest.approx(0.05, abs=0.03)
    assert '108 turns measured' in cand.note


def test_a_plain_scale_is_left_to_actuator_turn_error():
    cand = fitted(ActuatorResponse, [recorded(turn_calibration(), [ActuatorTurnError(0.8,
                                                                                     0.1)])])
    assert cand.effect is None and "actuator_turn_error's case" in cand.note


def test_the_plain_simulator_gives_none_and_missing_protocols_are_named():
    plain = [recorded(sweep(step=45.0, samples=60))]
    cand = fitted(ActuatorResponse, plain)
    assert cand.effect is None and 'record --protocol turns' in cand.note
    for cls in (LightResponse, SensorResponse):
        assert fitted(cls, plain).effect is None
    cand = fitted(LightResponse, [recorded(sweep(step=45.0, samples=20), [NARROW])])
    assert cand.effect is None and 'record --protocol sweep' in cand.note


def test_with_too_few_bearings_for_a_shape_no_table_is_made_and_the_sweep_is_named():
    """Section 2's few headings cannot show a shape: the levels are left to the effects
    that need no shape (a calibration), and the note names the protocol that would."""
    cand = fitted(LightResponse, [recorded(sweep(step=90.0, samples=30), [NARROW])])
    assert cand.effect is None and 'record --protocol sweep' in cand.note, cand.note
