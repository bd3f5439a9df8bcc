"""The emulated world's effects: configuration, each effect's physics, the default robot."""
import ast
from pathlib import Path

import numpy as np
import pytest

from khepera_noise_ros.core.khepera import World
from khepera_noise_ros.reality import effects
from khepera_noise_ros.reality.effects import EFFECTS, EffectsConfig
from khepera_noise_ros.reality.world import EmulatedWorld, stationary

ROOT = Path(__file__).resolve().parents[2]
QUIET = EffectsConfig.none(sensor_noise=0.0)


def corr(x, a, b):
    return np.corrcoef(x[:, a], x[:, b])[0, 1]


# --- configuration ---------------------------------------------------------------------

def test_effect_names_are_the_design_vocabulary():
    design = (ROOT / 'docs' / 'design.md').read_text()
    for name in set(EFFECTS) | {'none'}:
        assert f'`{name}`' in design
    assert set(effects.EFFECT_TYPES) == set(EFFECTS) and len(EFFECTS) == 7


def test_packaged_emulator_yaml_is_the_real_robot():
    assert EffectsConfig.load(ROOT / 'config' / 'emulator.yaml') == EffectsConfig.real_robot()


def test_the_previous_default_robot_stays_reachable():
    v1 = EffectsConfig.real_robot_v1()
    assert EffectsConfig.load(ROOT / 'config' / 'emulator_v1.yaml') == v1 != \
        EffectsConfig.real_robot()
    assert EffectsConfig.from_dict({'base': 'real_robot_v1'}) == v1
    assert v1.sensor_latency.strength == 1 and v1.sensor_latency.fraction == 0.0
    assert v1.actuator_turn_error.dead_band == v1.actuator_turn_error.asymmetry == 0.0
    assert v1.sensor_gain_offset.strength == 0.1


def test_yaml_round_trip(tmp_path):
    config = EffectsConfig.real_robot().only(
        'sensor_latency', 'saturation_quantization',
        sensor_latency={'strength': 3, 'location': [2, 3]})
    assert EffectsConfig.load(config.save(tmp_path / 'e.yaml')) == config
    assert config.enabled == ('sensor_latency', 'saturation_quantization')


def test_a_file_overrides_its_base():
    config = EffectsConfig.from_dict({'base': 'none', 'effects': {
        'temporal_drift': {'enabled': True, 'strength': 0.02}}})
    assert config.enabled == ('temporal_drift',)
    assert config.temporal_drift.strength == 0.02
    assert config.temporal_drift.time_constant == effects.TemporalDrift().time_constant
    assert EffectsConfig.from_dict({}) == EffectsConfig.real_robot()


@pytest.mark.parametrize('data, words', [
    ({'effects': {'flicker': {}}}, "unknown effect(s) ['flicker']"),
    ({'effects': {'temporal_drift': {'strength': 'x'}}},
     "effects.temporal_drift.strength must be a number in [0, 1], got 'x'"),
    ({'effects': {'correlated_noise': {'location': [[0, 1], [1, 2]]}}},
     'effects.correlated_noise.location: groups must not share sensors'),
    ({'effects': {'sensor_latency': {'location': [0, 9]}}},
     'effects.sensor_latency.location must be a non-empty list of distinct sensors'),
    ({'effects': {'sensor_latency': {'strength': 1.5}}},
     'effects.sensor_latency.strength must be an integer'),
    ({'effects': {'temporal_drift': {'enabled': 'yes'}}},
     "effects.temporal_drift.enabled must be true or false, got 'yes'"),
    ({'effects': {'actuator_turn_error': {'speed': 1}}},
     "effects.actuator_turn_error: unknown field(s) ['speed']"),
    ({'effects': {'saturation_quantization': {'low': 300, 'high': 200}}},
     'low must be below high'),
    ({'effects': {'sensor_gain_offset': {'gains': [1, 2]}}},
     'effects.sensor_gain_offset.gains must be null or a list of 8 numbers'),
    ({'sensor_noise': -0.1}, 'sensor_noise must be a number in [0, 1], got -0.1'),
    ({'base': 'ideal'},
     "base must be one of ['none', 'real_robot', 'real_robot_v1'], got 'ideal'"),
    ({'effects': {'actuator_turn_error': {'asymmetry': 1.5}}},
     'effects.actuator_turn_error.asymmetry must be a number in [-0.9, 0.9], got 1.5'),
    ({'effects': {'actuator_turn_error': {'dead_band': -1}}},
     'effects.actuator_turn_error.dead_band must be a number in [0, 180], got -1'),
    ({'effects': {'sensor_latency': {'fraction': 2}}},
     'effects.sensor_latency.fraction must be a number in [0, 1], got 2'),
    ({'format': 'other/1'}, 'format must be'),
    ({'colour': 1}, "unknown key(s) ['colour']")])
def test_bad_settings_name_the_key_and_value(data, words):
    with pytest.raises(ValueError) as exc:
        EffectsConfig.from_dict(data, 'my.yaml')
    assert str(exc.value).startswith('my.yaml: ') and words in str(exc.value)


def test_bad_yaml_file_is_a_clear_error(tmp_path):
    path = tmp_path / 'bad.yaml'
    path.write_text('effects: [unclosed')
    with pytest.raises(ValueError, match='not valid YAML'):
        EffectsConfig.load(path)


def test_reality_does_not_use_the_simulators_noise_model():
    for path in (ROOT / 'khepera_noise_ros' / 'reality').glob('*.py'):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                names = [node.module or ''] + [a.name for a in node.names]
                assert not any(n.endswith('noise') and 'core' in (node.module or '') + n
                               for n in names), f'{path.name} imports core.noise'


# --- each effect as a process ------------------------------------------------------------

def readings(config, condition='room_dark', samples=400, seed=3, bearing=0.0):
    return stationary(EmulatedWorld(config, seed=seed), condition, samples, bearing)


def test_no_effects_and_no_noise_is_the_simulators_light_table():
    world = EmulatedWorld(QUIET, robots=2)
    table = World().light_table()
    for tenths in (0, 123, 1800, 3333):
        world.set_bearing(tenths / 10.0)
        assert np.array_equal(world.read(), np.repeat(table[:, tenths][None], 2, axis=0))


def test_sensor_noise_is_independent_and_proportional():
    x = readings(EffectsConfig.none(sensor_noise=0.04))
    assert abs(corr(x, 2, 3)) < 0.15
    assert np.abs(x - 500).max() <= 0.04 * 500 + 1 and x.std(axis=0).min() > 5


def test_correlated_noise_is_shared_within_groups_only():
    x = readings(QUIET.only('correlated_noise', correlated_noise={
        'strength': 0.02, 'location': [[0, 1, 2], [3, 4, 5]]}))
    assert corr(x, 0, 2) > 0.95 and corr(x, 3, 5) > 0.95
    assert abs(corr(x, 2, 3)) < 0.2
    assert x[:, 6].std() == 0                                      # in no group


def test_intensity_dependent_noise_swings_more_and_together_in_the_dark():
    config = EffectsConfig.none(sensor_noise=0.01).only('intensity_dependent_noise')
    dark, bright = readings(config, 'room_dark'), readings(config, 'bulb_1ft')
    assert corr(dark, 2, 3) > 0.9 > 0.3 > corr(bright, 2, 3)
    assert np.ptp(dark[:, 2]) > 3 * np.ptp(bright[:, 2])


def test_gain_and_offset_belong_to_the_unit_not_the_run():
    config = QUIET.only('sensor_gain_offset')
    a, b = readings(config, seed=1, samples=3), readings(config, seed=2, samples=3)
    assert np.array_equal(a, b) and len(set(a[0])) > 4             # fixed, and per sensor
    other = QUIET.only('sensor_gain_offset', sensor_gain_offset={'unit_seed': 9})
    assert not np.array_equal(readings(other, samples=1), a[:1])
    fixed = QUIET.only('sensor_gain_offset', sensor_gain_offset={
        'gains': [1.0] * 8, 'offsets': [0, 0, 10, -10, 0, 0, 0, 0]})
    assert readings(fixed, 'bulb_2ft', samples=1)[0, 2] - \
        readings(QUIET, 'bulb_2ft', samples=1)[0, 2] == 10


def test_temporal_drift_is_slow():
    x = readings(QUIET.only('temporal_drift', temporal_drift={'strength': 0.02}), samples=600)
    d = x[:, 2] - x[:, 2].mean()
    assert np.corrcoef(d[1:], d[:-1])[0, 1] > 0.9                   # autocorrelated
    assert abs(corr(x, 2, 3)) < 0.5                                 # per sensor by default
    shared = QUIET.only('temporal_drift', temporal_drift={'strength': 0.02, 'shared': True})
    assert corr(readings(shared, samples=600), 2, 3) > 0.99


def test_actuator_turn_error_scales_and_slips():
    world = EmulatedWorld(QUIET.only('actuator_turn_error', actuator_turn_error={
        'scale': 0.9, 'strength': 0.05}), seed=4)
    actual = np.array([world.turn(20.0)[0] for _ in range(300)])
    assert actual.mean() == pytest.approx(18.0, abs=0.3)
    assert actual.std() == pytest.approx(1.0, rel=0.2)
    assert world.bearing_deg[0] == pytest.approx((actual.sum() + 180) % 360 - 180)
    exact = EmulatedWorld(QUIET)
    assert exact.turn(-7.5)[0] == -7.5 and exact.bearing_deg[0] == -7.5


def test_a_dead_band_and_unequal_motors_shape_each_turn():
    world = EmulatedWorld(QUIET.only('actuator_turn_error', actuator_turn_error={
        'strength': 0.0, 'scale': 1.0, 'dead_band': 3.0, 'asymmetry': 0.3}))
    assert world.turn(2.5)[0] == 0.0 and world.turn(-3.0)[0] == 0.0     # too small to start
    assert world.turn(10.0)[0] == pytest.approx(7.0 * 1.3)               # right: further
    assert world.turn(-10.0)[0] == pytest.approx(-7.0 * 0.7)             # left: less far
    assert world.bearing_deg[0] == pytest.approx(7.0 * 1.3 - 7.0 * 0.7)


def test_a_measurement_sees_part_of_the_last_turn():
    config = QUIET.only('sensor_latency', sensor_latency={'strength': 0, 'fraction': 0.25})
    world, ideal = EmulatedWorld(config), EmulatedWorld(QUIET)
    world.set_bearing(0.0)
    ideal.set_bearing(0.0)
    before = ideal.read(0).astype(float)
    assert np.array_equal(world.read(0), before)          # placed: no turn to mix
    assert np.array_equal(world.read(0), before)          # still: nothing changes
    world.turn(-40.0)
    ideal.turn(-40.0)
    after = ideal.read(0).astype(float)
    mixed = world.read(0)
    assert np.abs(mixed - (0.25 * before + 0.75 * after)).max() <= 0.5
    assert not np.array_equal(mixed, after)
    world.set_bearing(0.0)                                # placed again by hand
    assert np.array_equal(world.read(0), before)


def test_sensor_latency_reports_the_past():
    world = EmulatedWorld(QUIET.only('sensor_latency', sensor_latency={
        'strength': 2, 'location': [2]}))
    world.set_bearing(90.0)
    before = world.read(0)
    world.set_bearing(10.0)
    late, later, now = world.read(0), world.read(0), world.read(0)
    assert late[2] == later[2] == before[2] != now[2]
    assert late[0] == now[0] != before[0]                           # sensor 0 is not late


def test_saturation_and_quantisation():
    config = QUIET.only('saturation_quantization', saturation_quantization={
        'strength': 8.0, 'low': 100.0, 'high': 480.0, 'location': [0, 1, 2, 3, 4, 5]})
    x = readings(config, 'task', samples=1)[0]
    assert ((x[:6] % 8 == 0) | (x[:6] == 100)).all() and x[:6].min() == 100
    assert x[:6].max() == 480
    assert x[6] == 500                                              # outside the location


# --- the default robot and the paper's section 2 -----------------------------------------

def test_real_robot_reproduces_section_2():
    """Dimmer light: higher correlation of adjacent sensors and a wider range."""
    config = EffectsConfig.real_robot()
    x = {c: readings(config, c, samples=600, seed=0)
         for c in ('bulb_1ft', 'bulb_2ft', 'room_fluorescent', 'room_dark')}
    r = {c: corr(v, 2, 3) for c, v in x.items()}
    paper = {'bulb_1ft': 0.05, 'bulb_2ft': 0.85, 'room_fluorescent': 0.76, 'room_dark': 0.98}
    for c in paper:
        assert r[c] == pytest.approx(paper[c], abs=0.12), (c, r[c])
    assert r['bulb_2ft'] > r['bulb_1ft'] + 0.5 and r['room_dark'] > r['room_fluorescent']
    assert np.ptp(x['bulb_2ft'][:, 2]) > np.ptp(x['bulb_1ft'][:, 2])
    assert np.ptp(x['room_dark'][:, 2]) > np.ptp(x['room_fluorescent'][:, 2])


def test_robots_have_their_own_streams():
    batch = EmulatedWorld(seed=7, robots=3)
    alone = EmulatedWorld(seed=7, robots=3)
    together = np.stack([batch.read() for _ in range(5)])          # (5, 3, 8)
    assert np.array_equal(np.stack([alone.read(1) for _ in range(5)]), together[:, 1])
    assert not np.array_equal(together[:, 0], together[:, 1])
    some = EmulatedWorld(seed=7, robots=3)
    assert np.array_equal(np.stack([some.read([0, 2]) for _ in range(5)]), together[:, [0, 2]])


def test_world_refuses_bad_input():
    world = EmulatedWorld(robots=2)
    with pytest.raises(ValueError, match='unknown lighting condition'):
        world.set_condition('moonlight')
    with pytest.raises(ValueError, match='robot must be an index in'):
        world.read(2)
    with pytest.raises(ValueError, match='distinct'):
        world.read([1, 1])
    with pytest.raises(ValueError, match='finite'):
        world.set_bearing(np.nan)
    with pytest.raises(ValueError, match='robots must be an integer'):
        EmulatedWorld(robots=0)
