"""The emulated robot's effects against the simulator's: where in the chain each acts.

A sensor's converter saturates the noisy reading once, at the end; the simulator
used to clip the light level before adding its noise, so a level that a light-stage
effect (a gain, a flicker) took beyond the range read the range's end plus noise,
and half of those readings fell back inside it.  On the emulated robot that made
the true effects leave a value-lattice gap (the pile at 525 of the darkest
readings) that hid its group noise and its drift (docs/diagnosis.md, "The emulated
robot's effects as a set").
"""
import sys
from pathlib import Path

import numpy as np
import pytest

from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.gap import compound, simulate
from khepera_noise_ros.gap import effects as fx

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'benchmark'))

NOISE = NoiseModel.independent_only(0.02)
RAISED = fx.SensorGainOffset((0, 1, 2, 3, 4, 5, 6, 7), (1.0,) * 8, (20.0,) * 8)


def test_a_level_beyond_the_range_saturates_the_reading_in_a_stationary_run():
    """Light at 520 raised by 20 (an offset) is 540 before the noise of +-2% (at most
    11): every reading is the converter's end, 525, at either rounding."""
    base = np.full((400, 8, 3), 520.0)
    for rounding in ('level', 'reading'):
        noise = NoiseModel.independent_only(0.02, rounding=rounding)
        out = simulate.stationary(base, noise, [RAISED], seed=4)
        assert np.all(out == 525.0), (rounding, np.unique(out))
    # below the end nothing changes: the offset and the noise as before
    low = simulate.stationary(np.full((400, 8, 3), 300.0), NOISE, [RAISED], seed=4)
    assert low.min() < 320.0 < low.max() and np.all(np.abs(low - 320.0) <= 7.0)


def test_a_level_beyond_the_range_saturates_the_reading_in_closed_loop_sensing():
    """The same through the episodes' sensing (``sense``: the closed loop, the node)."""
    from khepera_noise_ros.core.streams import UNIT
    rng = np.random.default_rng(0)
    draws = rng.integers(0, int(UNIT) + 1, size=(8, 500), dtype=np.uint16)
    light = [RAISED.process(500, 8, rng)]
    out = simulate.sense(np.full((8, 500), 520.0), NOISE, draws, draws[:1], light, [])
    assert np.all(out == 525.0), np.unique(out)


def test_a_saturating_flicker_leaves_no_pile_up_gap_with_its_true_parameters():
    """The emulated robot with only its flicker (6%, darker readings more) and its own
    sensor noise: in the dark room many readings sit at 525.  The simulator given the
    flicker's true parameters reproduces the pile there (the statistics of the value
    lattice: pile-up, mode share, granularity) at the paper's rounding."""
    import emulated_set as es
    from khepera_noise_ros.reality.effects import EffectsConfig
    config = EffectsConfig.real_robot().only('intensity_dependent_noise')
    recs = es.recordings(config, 3, 60, 2)[:1]
    _, held = es.parts(recs, config)
    c = held.compare([es.true_effects(config)['intensity_dependent_noise']])
    lattice = {f: d for f, d in es._by_family(c) if f in ('pileup', 'mode_share',
                                                          'granularity')}
    assert sum(lattice.values()) < 20.0, lattice


@pytest.fixture(scope='module')
def oracle_240():
    """The emulated robot's six effects with their true parameters in the simulator
    (the paper's rounding), on the held-out half of a recording with 240 samples per
    heading: (target, its comparison with all six, the true effects)."""
    import emulated_set as es
    from khepera_noise_ros.reality.effects import EffectsConfig
    config = EffectsConfig.real_robot()
    recs = es.recordings(config, 3, 240, 2)[:1]
    _, held = es.parts(recs, config)
    true = es.true_effects(config)
    return held, held.compare(list(true.values())), true


def test_the_robots_true_effects_leave_little_of_the_value_lattice(oracle_240):
    """All six true effects leave the lattice statistics almost nothing (they left 1,282
    of 1,293 before the reading saturated once)."""
    import emulated_set as es
    _, all_six, _ = oracle_240
    lattice = sum(d for f, d in es._by_family(all_six)
                  if f in ('pileup', 'mode_share', 'granularity'))
    assert lattice < 100.0, es._by_family(all_six)


def test_leaving_the_robots_group_noise_out_raises_the_held_out_discrepancy(oracle_240):
    """The group noise (0.3% in three groups) is a real part of the robot: without it the
    held-out discrepancy rises significantly (paired bootstrap).  Before, at the
    paper's rounding, leaving it out lowered the discrepancy (1,293 to 1,181)."""
    held, all_six, true = oracle_240
    rest = held.compare([e for n, e in true.items() if n != 'correlated_noise'])
    p = compound.paired_p(held.replicate_discrepancies(rest),
                          held.replicate_discrepancies(all_six), rest.discrepancy,
                          all_six.discrepancy)
    assert rest.discrepancy > all_six.discrepancy + 50.0 and p < 0.05, \
        (rest.discrepancy, all_six.discrepancy, p)


def test_given_the_robots_true_effects_the_papers_rounding_is_kept():
    """The benchmark's robot truncates its noise as the paper's getnoise does and rounds
    once at the end: rint(level + trunc(noise)) is rint(level) + trunc(noise), the
    paper's rounding at the level.  Given the robot's true effects the value-lattice
    statistics keep it (``gap.rounding``); before, with the level clipped, they chose
    rounding at the reading (the pile at 525 it restored stood for the saturation)."""
    import emulated_set as es
    from khepera_noise_ros.gap import rounding
    from khepera_noise_ros.reality.effects import EffectsConfig
    config = EffectsConfig.real_robot()
    recs = es.recordings(config, 3, 60, 2)[:1]
    fit_part, _ = es.parts(recs, config)
    choice = rounding.choose(fit_part, list(es.true_effects(config).values()))
    assert choice['given'] == 'level' and choice['rounding'] == 'level', choice
    assert choice['lattice']['level'] < choice['lattice']['reading'], choice
