"""The foreign robots (benchmark/foreign): drawn as committed, driven alike in process and
on a pty, refused when malformed, different in form from the simulator, and kept apart
from what fits a simulator to a robot."""
import ast
import json
from pathlib import Path

import numpy as np
import pytest

from khepera_noise_ros.core import network
from khepera_noise_ros.core.evolution import EAConfig
from khepera_noise_ros.core.khepera import SENSOR_ANGLES_DEG, World, turn
from khepera_noise_ros.core.task import Task
from khepera_noise_ros.reality.emulator import Emulator
from khepera_noise_ros.reality.khepera_robot import InProcessRobots, KheperaRobots

from . import actuator, learnability, params
from . import cli as foreign_robots
from .draw import draw_robot
from .robot import ForeignWorld
from .sensing import Sensing

ROOT = Path(__file__).resolve().parents[2]

FILES = sorted((ROOT / 'benchmark' / 'foreign' / 'robots').glob('foreign_*.yaml'))
NAMES = [p.stem for p in FILES]
GENOME = np.random.default_rng(3).uniform(-2.0, 2.0, (1, 20))


@pytest.fixture(scope='module')
def robots():
    return {p.stem: params.load(p) for p in FILES}


def test_at_least_eight_robots_are_committed_and_each_is_its_generators_draw(robots):
    assert len(robots) >= 8
    for name, p in robots.items():
        drawn = draw_robot(p['drawn']['seed'], p['drawn']['index'])
        assert drawn['name'] == name
        for section in ('light', 'actuator', 'dynamics', 'noise'):
            for key, value in p[section].items():
                if isinstance(value, str):
                    assert value == drawn[section][key], (name, key)
                else:          # the file keeps 4 significant digits
                    np.testing.assert_allclose(value, drawn[section][key], rtol=1e-3,
                                               atol=1e-6, err_msg=f'{name} {key}')


def _episode(env, steps_seed=5, bearing=None):
    """Readings of every step of one episode of a fixed controller, per copy."""
    weights = network.unpack(np.repeat(GENOME, 2, axis=0))
    readings = env.reset([steps_seed, steps_seed + 1], bearing_deg=bearing)
    seen = []
    while readings is not None:
        seen.append(readings.copy())
        readings = env.step(*network.act(weights, readings))
    return np.stack(seen)


@pytest.mark.parametrize('name', NAMES[:3])
def test_a_robot_reads_the_same_in_process_and_on_a_pty_for_the_same_seed(robots, name):
    p = robots[name]
    task = Task(steps=15)
    bulb = World(lamp_distance_mm=130.0)             # a condition declared with Z,L
    world = ForeignWorld(p, 2)
    closed = _episode(KheperaRobots(InProcessRobots(world), World(), task))
    still = _episode(KheperaRobots(InProcessRobots(world), bulb,
                                   Task(steps=8, perturbation_deg=0.0)), bearing=35.0)
    with Emulator(ForeignWorld(p, 2)) as emulator:
        there = KheperaRobots.on_ports(emulator.ports, World(), task)
        try:
            assert np.array_equal(_episode(there), closed)
        finally:
            there.close()
        far = KheperaRobots.on_ports(emulator.ports, bulb, Task(steps=8, perturbation_deg=0.0))
        try:
            assert np.array_equal(_episode(far, bearing=35.0), still)
        finally:
            far.close()
        served = emulator.served(0)
    assert served['O'] == 15 + 8 and served['C'] > 0 and served['Z'] > 0
    assert np.ptp(closed[:, 0, :6]) > 50          # the readings move: the robot turned


def test_a_copys_readings_do_not_depend_on_the_other_copies(robots):
    p = robots[NAMES[0]]
    alone, batch = ForeignWorld(p, 3), ForeignWorld(p, 3)
    for world in (alone, batch):
        world.set_condition('task')
    for k in range(5):
        alone.turn(7.0, 1)
        batch.turn([-3.0, 7.0, 12.0])
        assert np.array_equal(alone.read(1), batch.read()[1])


def _bad(tmp_path, change):
    data = params.plain(draw_robot(26, 0))
    change(data)
    path = tmp_path / 'bad.yaml'
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize('change, words', [
    (lambda d: d['actuator'].update(gain=-1.0), 'actuator.gain must be a number in [0.2, 3.0]'),
    (lambda d: d['light'].update(floor=[40.0] * 7), 'light.floor must be 8 numbers'),
    (lambda d: d['noise'].pop('shot'), 'noise.shot must be given'),
    (lambda d: d['noise'].update(colour='pink'), 'noise.colour must be one of the keys'),
    (lambda d: d['dynamics'].update(kind='wobble'), 'dynamics.kind must be one of'),
    (lambda d: d['light'].update(dark=[200.0] * 8, floor=[195.0] * 8),
     'at least 10 below light.dark[0]'),
    (lambda d: d.update(format='other/1'), "format must be 'khepera-foreign-robot/1'"),
])
def test_a_bad_parameter_file_is_refused_in_one_line(tmp_path, capsys, change, words):
    path = _bad(tmp_path, change)
    with pytest.raises(ValueError) as error:
        params.load(path)
    message = str(error.value)
    assert words in message and str(path) in message and '\n' not in message
    assert foreign_robots.main(['serve', str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and words in err


def test_a_file_that_is_not_yaml_or_missing_is_refused_in_one_line(tmp_path):
    (tmp_path / 'x.yaml').write_text('light: [unclosed')
    for path, words in ((tmp_path / 'x.yaml', 'not YAML'),
                        (tmp_path / 'none.yaml', 'cannot read')):
        with pytest.raises(ValueError, match=words) as error:
            params.load(path)
        assert '\n' not in str(error.value)
    with pytest.raises(ValueError, match='no foreign robot'):
        foreign_robots.robot_path('foreign_999')


def test_a_drawn_robot_is_never_overwritten(tmp_path):
    p = draw_robot(26, 0)
    params.save(p, tmp_path / 'r.yaml')
    with pytest.raises(ValueError, match='written once'):
        params.save(p, tmp_path / 'r.yaml')
    assert params.load(tmp_path / 'r.yaml')['unit_seed'] == p['unit_seed']


# --- different in form from the simulator -------------------------------------------------

OFFSETS = np.arange(-40.0, 41.0, 5.0)


def lobe_profiles(response) -> np.ndarray:
    """Each front sensor's drop below its lamp-off reading over the lamp's offset from the
    sensor's nominal axis, normalised to its largest: (6, offsets)."""
    axes = np.asarray(SENSOR_ANGLES_DEG[:6])
    drop = np.array([[response(a + d)[i] for d in OFFSETS] for i, a in enumerate(axes)])
    drop = response(None)[None, :6].T - drop
    return drop / drop.max(axis=1, keepdims=True)


def same_form_as_the_simulator(profiles: np.ndarray) -> bool:
    """The simulator's lobes: symmetric about the nominal axis and one shape for all."""
    asymmetry = np.abs(profiles - profiles[:, ::-1]).max()
    spread = np.ptp(profiles, axis=0).max()
    return asymmetry < 0.02 and spread < 0.02


def sim_response(world: World):
    def response(bearing):
        if bearing is None:
            return np.full(8, world.ambient)
        return world.response(bearing - np.asarray(SENSOR_ANGLES_DEG))
    return response


def foreign_response(p):
    world = ForeignWorld(p)
    world.set_condition('bulb_2ft')         # mid-range: no reading pinned at a floor

    def response(bearing):
        if bearing is None:
            world.set_condition('room_dark')
            out = world.clean(np.arange(1))[0]
            world.set_condition('bulb_2ft')
            return out
        world.set_bearing(bearing, 0)
        return world.clean(np.arange(1))[0]
    return response


def test_the_form_check_knows_the_simulators_light_response():
    for world in (World(lamp_distance_mm=130.0), World(lamp_distance_mm=60.0, gain=300.0,
                                                       half_angle_deg=80.0)):
        assert same_form_as_the_simulator(lobe_profiles(sim_response(world)))


@pytest.mark.parametrize('name', NAMES)
def test_a_robots_light_response_differs_in_form_from_the_simulators(robots, name):
    assert not same_form_as_the_simulator(lobe_profiles(foreign_response(robots[name])))


def turns_by_power(execute) -> np.ndarray:
    """Mean executed turn for commanded power -9 .. 9 (3 deg each), degrees."""
    return np.array([execute(3.0 * p) for p in range(-9, 10)])


def linear_and_symmetric(executed: np.ndarray) -> bool:
    """The simulator's turn: the same degrees per unit of power, both ways."""
    power = np.arange(-9, 10)
    moving = power != 0
    per_power = executed[moving] / power[moving]
    return np.ptp(per_power) < 0.05 * np.abs(per_power).mean() and executed[9] == 0


def test_the_turn_check_knows_the_simulators_turning():
    def sim(deg):
        return float(turn(np.zeros(1, np.int64), np.sign([deg]).astype(np.int64),
                          np.array([abs(deg) / 3.0]).astype(np.int64), World())[0]) / 10.0
    assert linear_and_symmetric(turns_by_power(sim))


@pytest.mark.parametrize('name', NAMES)
def test_a_robots_turning_differs_in_form_from_the_simulators(robots, name):
    p = robots[name]
    assert not linear_and_symmetric(turns_by_power(
        lambda deg: float(actuator.mean_turn(p['actuator'], deg))))
    world = ForeignWorld(p, robots=400)                  # the world turns by the same law
    world.set_condition('task')
    made = world.turn(np.full(400, 15.0))
    expected = float(actuator.mean_turn(p['actuator'], 15.0))
    assert abs(np.median(made) - expected) < 0.1 * expected + 0.2
    assert np.std(made) > 0                              # with scatter
    small = world.turn(np.full(400, -2.0 * p["actuator"]["dead_band_deg"] / 3.0))
    assert np.all(small == 0.0)                          # small commands stay in the dead-band


@pytest.mark.parametrize('name', NAMES)
def test_a_robots_sensors_answer_late_where_the_simulators_answer_at_once(robots, name):
    p = robots[name]
    sensing = Sensing(p, 1, np.zeros(1))
    rows = np.arange(1)
    before, after = np.full((1, 8), 480.0), np.full((1, 8), 100.0)
    sensing.settle(rows, before)
    quiet = dict(p, noise=dict(p['noise'], shot=0.0))
    sensing.noise = quiet['noise']
    first = sensing.measure(rows, after, np.zeros((1, 8)))
    assert np.all(first > 120.0)                        # not yet at the new light
    for _ in range(40):
        last = sensing.measure(rows, after, np.zeros((1, 8)))
    assert np.all(np.abs(last - 100.0) <= p['noise']['step'])


# --- kept apart, and learnable ------------------------------------------------------------

FORBIDDEN = ('khepera_noise_ros.gap', 'khepera_noise_ros.reality.effects',
             'khepera_noise_ros.reality.world', 'khepera_noise_ros.nodes.simulator')


def test_the_generator_imports_nothing_that_fits_a_simulator_to_a_robot():
    files = sorted((ROOT / 'benchmark' / 'foreign').glob('*.py')) + \
        [ROOT / 'benchmark' / 'foreign_robots.py']
    imported = set()
    for path in files:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and not node.level:
                imported |= {node.module} | {f'{node.module}.{a.name}' for a in node.names}
            elif isinstance(node, ast.Import):
                imported |= {a.name for a in node.names}
    assert any(m.startswith('khepera_noise_ros.core') for m in imported)
    assert not [m for m in imported if m.startswith(FORBIDDEN)], imported


def test_the_committed_table_applies_the_rule_and_leaves_at_least_six_robots():
    data = json.loads(foreign_robots.RESULTS.read_text())
    assert data['trials'] >= 10 and data['test_episodes'] >= 10
    assert set(data['robots']) == set(NAMES)
    for name, r in data['robots'].items():
        arms = {k: np.asarray(v) for k, v in r['values'].items()}
        d = learnability.welch(arms['ceiling'], arms['stock'])
        gap = learnability.paired(arms['sim'], arms['stock'])
        assert d['mean'] == pytest.approx(r['difference']['mean'])
        rule = d['mean'] > learnability.MARGIN and d['low'] > 0 and gap['low'] > 0
        assert r['counts'] == rule, name
    assert len(foreign_robots.benchmark_robots()) >= 6


def test_learnability_runs_end_to_end_at_a_tiny_budget(robots, monkeypatch):
    monkeypatch.setattr(learnability, 'CAPACITY', 8)
    tiny = EAConfig(population=4, generations=2, best='retest', retest_episodes=2)
    stock = learnability.stock_controllers(1, 2, tiny)
    r = learnability.measure(robots[NAMES[0]], stock, 1, test_episodes=2, ea=tiny)
    assert {'sim', 'stock', 'ceiling', 'scratch', 'difference', 'gap'} <= set(r)
    assert len(r['values']['ceiling']) == 2 and r['learnable'] in (True, False)
    assert all(0.0 <= v <= 1.0 for arm in r['values'].values() for v in arm)
