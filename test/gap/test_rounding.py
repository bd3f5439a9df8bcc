"""Where the reading is rounded: a simulator setting, and the diagnosis choosing it.

The paper's simulator adds integer noise to an integer light level; a sensor's
converter rounds the noisy analogue signal once ('reading').  The setting changes
which values the readings take (the value lattice); the diagnosis chooses it from
the data and must keep the paper's setting on recordings made with it (controls).
"""
import copy
import dataclasses
import types

import numpy as np
import pytest

from khepera_noise_ros.core.khepera import SENSOR_ANGLES_DEG, SENSORS, World
from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.core.task import Episodes, Task
from khepera_noise_ros.effects import CorrelatedNoise, SensorGainOffset, SensorLatency
from khepera_noise_ros.effects.simulate import EffectEpisodes, stationary
from khepera_noise_ros import simconfig
from khepera_noise_ros.experiment import diagnosis_report as report
from khepera_noise_ros.effects.base import Key
from khepera_noise_ros.gap import diagnose, select
from khepera_noise_ros.gap.compare import Comparison
from khepera_noise_ros.simconfig import SimConfig
from khepera_noise_ros.gap.target import Target
from khepera_noise_ros.testing.comparisons import replicate_discrepancies
from khepera_noise_ros.testing.protocols import CONFIG, recorded, stationary_protocol

READING = diagnose.with_rounding(CONFIG, 'reading')


def test_the_rounding_is_a_setting_of_the_noise_model_with_the_papers_as_default():
    assert NoiseModel().rounding == 'level'
    assert NoiseModel(rounding='reading').rounding == 'reading'
    with pytest.raises(ValueError, match=r"rounding must be one of \('level', 'reading'\), "
                                         r"got 'floor'"):
        NoiseModel(rounding='floor')


def test_rounding_the_reading_once_spreads_a_bright_sensors_small_noise_over_two_values():
    """Light level 40.3, 1% noise (at most 0.4): the paper's integer noise truncates to
    0, so every reading is 40; noise added before one rounding gives 41 whenever the sum
    reaches 40.5, a quarter of the time."""
    base = np.full((4000, 8, 1), 40.3)
    level = stationary(base, NoiseModel.independent_only(0.01), seed=1)
    assert np.unique(level).tolist() == [40.0]
    reading = stationary(base, NoiseModel.independent_only(0.01, rounding='reading'), seed=1)
    assert set(np.unique(reading).tolist()) == {40.0, 41.0}
    assert abs(np.mean(reading == 41.0) - (40.3 + 0.403 - 40.5) / 0.806) < 0.03


def test_either_rounding_clips_once_at_the_end():
    """A level beyond the dark end stays beyond it until the end, at either setting (a
    converter saturates the noisy reading): with a light-stage offset of +10 on a
    reading of 520 (530) and noise of +-3% (at most 15.9), readings reach down to 514
    and no lower, and about two thirds read 525."""
    base = np.full((3000, 8, 1), 520.0)
    offset = SensorGainOffset(tuple(range(8)), (1.0,) * 8, (10.0,) * 8)
    level = stationary(base, NoiseModel.independent_only(0.03), (offset,), seed=2)
    reading = stationary(base, NoiseModel.independent_only(0.03, rounding='reading'),
                         (offset,), seed=2)
    for out in (level, reading):
        assert out.min() >= 514 and np.mean(out == 525) > 0.6


def test_closed_loop_episodes_add_the_noise_to_the_unrounded_light():
    """The core's episodes and the simulator node's (EffectEpisodes) read the unrounded
    light table when the reading is rounded at the end: averaged over many robots the
    readings find the light's fraction, which the integer table has lost."""
    world, task = World(), Task(perturbation_deg=0.0)
    light = world.response(-np.asarray(SENSOR_ANGLES_DEG))
    off = np.abs(light - np.rint(light)) > 0.2          # sensors whose fraction shows
    assert off.any()
    for episodes in (Episodes, EffectEpisodes):
        means = {}
        for mode in ('level', 'reading'):
            env = episodes(world, NoiseModel.independent_only(0.02, rounding=mode), task)
            means[mode] = env.reset(7, robots=40000).mean(axis=0)
        assert np.all(np.abs(means['reading'] - light)[off] < 0.1), means['reading'] - light
        assert np.all(np.abs(means['level'] - np.rint(light))[off] < 0.1)
    # the node's episodes with an effect give the same readings as without one that acts
    plain = EffectEpisodes(world, NoiseModel.independent_only(0.02, rounding='reading'), task)
    latent = EffectEpisodes(world, NoiseModel.independent_only(0.02, rounding='reading'), task,
                            (SensorLatency((0,), 1),))
    first = plain.reset(3, robots=50)
    assert first.shape == (50, SENSORS) and np.array_equal(first, np.rint(first))
    assert np.array_equal(latent.reset(3, robots=50)[:, 1:], first[:, 1:])


def test_the_rounding_goes_through_the_params_file_and_bad_values_are_refused(tmp_path):
    config = dataclasses.replace(READING, effects=(SensorLatency((1,), 1),))
    assert config.parameters()['rounding'] == 'reading'
    path = simconfig.write(config, tmp_path / 'fitted_params.yaml')
    assert simconfig.load(path) == config
    assert simconfig.from_parameters({}).noise.rounding == 'level'      # an older file
    with pytest.raises(ValueError, match=r"^p.yaml: rounding must be one of .*got 'late'$"):
        simconfig.from_parameters({'rounding': 'late'}, 'p.yaml')


def test_the_simulator_node_loads_the_rounding_and_refuses_a_bad_one(tmp_path, ros_context):
    import rclpy

    from khepera_noise_ros.nodes.params import noise_from
    from khepera_noise_ros.nodes.simulator import Simulator
    path = simconfig.write(READING, tmp_path / 'fitted_params.yaml')
    node = Simulator(context=ros_context, cli_args=['--ros-args', '--params-file', str(path)])
    try:
        value = node.get_parameter('rounding').value
        rounding_used = node.backend.noise.rounding
        refused = node.set_parameters([rclpy.parameter.Parameter('rounding', value='late')])
        kept = node.get_parameter('rounding').value
    finally:
        node.destroy_node()
    assert value == 'reading' and rounding_used == 'reading'
    assert not refused[0].successful and 'late' in refused[0].reason and kept == 'reading'
    values = {'noise_model': 'independent', 'dependent_level': 0.0, 'independent_level': 0.02,
              'dependence_groups': '', 'distribution': 'uniform'}
    assert noise_from(values).rounding == 'level'             # a node without the parameter
    with pytest.raises(ValueError, match=r"^rounding must be one of .*got 'late'$"):
        noise_from(dict(values, rounding='late'))


# --- the diagnosis chooses it ------------------------------------------------------------

HIDDEN = ([], [CorrelatedNoise(((0, 5), (1, 3)), 0.02)],
          [SensorGainOffset((2, 5), (1.1, 0.9), (8.0, -6.0))])


@pytest.mark.parametrize('hidden', HIDDEN, ids=['none', 'pairs', 'calibration'])
def test_the_lattice_prefers_the_rounding_the_recording_was_made_with(hidden, lattice_choice):
    """Recordings made by a simulator that rounds the reading are told from the
    paper's simulator by their value lattice, given the hidden effect; recordings made
    by the paper's simulator (controls) keep it, whichever side is asked."""
    protocol = stationary_protocol(samples=60)
    for seed in (5, 6):
        made_reading = recorded(protocol, hidden, config=READING, seed=seed)
        made_level = recorded(protocol, hidden, seed=seed)
        assert lattice_choice(Target([made_reading], CONFIG, 1), hidden)['rounding'] \
            == 'reading'
        control = lattice_choice(Target([made_level], CONFIG, 1), hidden)
        assert control['rounding'] == 'level', control
        assert lattice_choice(Target([made_level], READING, 1), hidden)['rounding'] \
            == 'level'
        assert lattice_choice(Target([made_reading], READING, 1), hidden)['rounding'] \
            == 'reading'


def test_the_diagnosis_rounds_the_reading_when_the_robot_does_and_writes_it(tmp_path):
    """A robot with 1% sensor noise and shared noise in two pairs that rounds once at
    its converter, diagnosed against the paper's simulator at 1%: the diagnosis chooses
    the rounding (its bright readings' small noise shows on the value lattice), finds
    the pairs and nothing else, and fitted_params.yaml loads both.  The same robot
    rounding as the paper's simulator does (a control) keeps the paper's rounding."""
    low = SimConfig(noise=NoiseModel.independent_only(0.01))
    hidden = [CorrelatedNoise(((0, 5), (1, 3)), 0.01)]
    options = diagnose.Options(config=low, replicates=60)
    rec = recorded(stationary_protocol(samples=60), hidden,
                   config=diagnose.with_rounding(low, 'reading'), seed=5)
    result = diagnose.diagnose([rec], options)
    assert result.rounding['rounding'] == 'reading', result.rounding
    assert result.to_json()['rounding']['given'] == 'level'
    lattice = result.rounding['lattice_held_out']
    assert lattice['reading'] < 0.1 * lattice['level']
    assert [c['name'] for c in result.to_json()['compound']['chosen']] == ['correlated_noise']
    assert sorted(map(sorted, result.fitted.location)) == [[0, 5], [1, 3]]
    paths = report.write(result, tmp_path, low, figures=False)
    loaded = simconfig.load(paths['params'])
    assert loaded.noise.rounding == 'reading'
    assert [e.name for e in loaded.effects] == ['correlated_noise']
    control = diagnose.diagnose([recorded(stationary_protocol(samples=60), hidden, config=low,
                                          seed=5)], options)
    assert control.rounding['rounding'] == 'level', control.rounding
    assert control.top_effect == 'correlated_noise'


# -- the rounding asked again given the whole compound ----------------------------------

LATTICE = [Key('granularity', (s,), 'c', 'mod 2') for s in range(4)]
LEVELS = [Key('level', (s,), f'c{j}', None) for s in range(4) for j in range(10)]
KEYS = LATTICE + LEVELS


class Rounded:
    """What the rounding choice asks of a ``Target``: comparisons whose simulated side
    depends only on where its config rounds (``z``: rounding -> (lattice z, level z)),
    real bootstrap replicates, and a copy with another config."""

    def __init__(self, z, seed=0):
        rng = np.random.default_rng(seed)
        self.z, self.config = z, CONFIG
        self.real = rng.normal(100.0, 5.0, len(KEYS))
        self.reps = self.real + rng.normal(0.0, 1.0, (200, len(KEYS)))

    def compare(self, effects=(), replicates=None):
        lattice, level = self.z[self.config.noise.rounding]
        sim = self.real - np.r_[np.full(len(LATTICE), lattice), np.full(len(LEVELS), level)]
        return Comparison(list(KEYS), self.real, sim, np.ones(len(KEYS)), self.real - sim)

    def replicate_discrepancies(self, c):
        return replicate_discrepancies(KEYS, self.reps, c)

    def with_config(self, config):
        out = copy.copy(self)
        out.config = config
        return out


def _late(held_out_level_z):
    """A compound of two effects chosen with the paper's rounding kept at the first ask;
    asked again, rounding the reading leaves the lattice statistics at z 0 (z 6 at the
    level) on both parts, and the held-out levels at ``held_out_level_z`` (3 at the
    level)."""
    a = Rounded({'level': (6.0, 0.0), 'reading': (0.0, 0.0)})
    b = Rounded({'level': (6.0, 3.0), 'reading': (0.0, held_out_level_z)}, seed=1)
    effects = [SensorGainOffset((0,), (1.1,), (2.0,)), SensorLatency((1,), 1)]
    c = b.compare(effects)
    compound = select.Compound(effects, [], 1e4, c.discrepancy, c)
    result = types.SimpleNamespace(compound=compound, notes=[], rounding={
        'rounding': 'level', 'given': 'level', 'lattice': {'level': 1.0, 'reading': 1.0},
        'p_value': 0.5, 'note': 'the level is kept'})
    a2, b2 = diagnose._late_rounding(result, a, b, diagnose.Options())
    return result, compound, (a, b), (a2, b2)


def test_the_rounding_asked_again_given_the_compound_switches_where_it_brings_it_closer():
    result, compound, before, after = _late(3.0)
    assert result.rounding['early']['rounding'] == 'level'
    assert result.rounding['rounding'] == 'reading', result.rounding['note']
    assert [t.config.noise.rounding for t in after] == ['reading', 'reading']
    assert compound.discrepancy_after < before[1].compare().discrepancy
    assert compound.comparison.discrepancy == compound.discrepancy_after
    assert result.notes == [result.rounding['note']]


def test_the_rounding_asked_again_is_not_kept_where_the_compound_does_no_better():
    """The lattice prefers the reading, but the held-out levels move away (z 3 -> 5)."""
    result, compound, before, after = _late(5.0)
    assert result.rounding['rounding'] == 'level'
    assert 'does not fall' in result.rounding['note'], result.rounding['note']
    assert after == before and result.notes == []
    assert compound.discrepancy_after == before[1].compare().discrepancy
