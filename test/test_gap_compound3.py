"""Compound selection beside a dominant loop effect (a latency or a turn error).

The 'robot' is the emulated one (``reality``) with the effects set, recorded as
``benchmark/blind_gap.py`` records (closed loop with the lamp's bearing kept, as from
a tracked robot); the diagnosis sees only the recordings and the paper's independent
model at the robot's noise level.
"""
import dataclasses
import sys
from pathlib import Path

import numpy as np

from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.gap import compound, diagnose
from khepera_noise_ros.gap import effects as fx
from khepera_noise_ros.simconfig import SimConfig
from khepera_noise_ros.gap.statistics import Key
from khepera_noise_ros.gap.where import Comparison

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'benchmark'))
from blind_gap import evolved_genome, record_closed_loop, robot  # noqa: E402
from khepera_noise_ros.reality.effects import EffectsConfig  # noqa: E402

OPTIONS = diagnose.Options(config=SimConfig(noise=NoiseModel.independent_only(0.02)),
                           remainder=False)


def test_a_turn_error_beside_a_latency_that_took_its_share():
    """A latency of three steps on two sensors, turns 1.35 times the commanded and a
    small calibration error on a third sensor (case 21 of ``blind_compound.py --hard
    --seed 0``).  The latency, fitted alone first, takes part of the turn error's share
    (its sensor set bends to the turns); given it the turn error fitted the wrong way
    (scale 0.87) and made the closed loop worse, and a spread law came in instead
    (held-out shrink 0.65).  Fitted without the latency, the latency then refitted
    given it, the pair is found."""
    config = EffectsConfig.none(0.02).only(
        'sensor_latency', 'actuator_turn_error', 'sensor_gain_offset',
        sensor_latency={'strength': 3, 'location': (0, 1)},
        actuator_turn_error={'scale': 1.3472112889087093, 'strength': 0.18200775202216513},
        sensor_gain_offset={'gains': (1, 1, 0.9579582001682678, 1, 1, 1, 1, 1),
                            'offsets': (0, 0, -2.465462814917963, 0, 0, 0, 0, 0),
                            'location': (2,)})
    seed = 1455561792
    recording = record_closed_loop(robot(config, seed), evolved_genome(0), seed=seed,
                                   headings=True)
    result = diagnose.diagnose([recording], dataclasses.replace(OPTIONS, seed=21)).to_json()
    chosen = result['compound']['chosen']
    names = [c['name'] for c in chosen]
    assert {'sensor_latency', 'actuator_turn_error'} <= set(names), chosen
    assert 'intensity_dependent_noise' not in names, chosen
    turn = next(c for c in chosen if c['name'] == 'actuator_turn_error')
    assert 1.2 < turn['parameters']['scale'] < 1.5, turn
    assert result['compound']['heldout_reduction'] > 0.9


def _cmp(parts: dict) -> Comparison:
    """A made-up comparison with one statistic per part, of discrepancy ``parts[part]``."""
    family = {'stationary': 'spread', 'closed_loop': 'turn_power',
              'closed_loop_noise': 'loop_residual_spread'}
    keys = [Key(family[p], (0,), 'task', None) for p in parts]
    z = np.array([2.0 + np.sqrt(d) for d in parts.values()])
    return Comparison(keys, z, np.zeros(len(z)), np.ones(len(z)), z)


def test_a_step_closer_in_one_part_and_away_in_another_is_refitted_jointly():
    current = _cmp({'stationary': 100.0, 'closed_loop': 50.0})
    assert compound._confounded(current, _cmp({'stationary': 60.0, 'closed_loop': 80.0}))
    # closer in both, or closer only by a sliver, or away within chance: not confounded
    assert not compound._confounded(current, _cmp({'stationary': 60.0, 'closed_loop': 40.0}))
    assert not compound._confounded(current, _cmp({'stationary': 99.0, 'closed_loop': 80.0}))
    small = _cmp({'stationary': 100.0, 'closed_loop': 0.1})
    assert not compound._confounded(small, _cmp({'stationary': 60.0, 'closed_loop': 0.2}))


def test_only_a_second_loop_effect_is_fitted_without_the_first():
    latency = fx.SensorLatency((0, 1), 2)
    assert compound._other_loop([latency], 'actuator_turn_error')
    assert not compound._other_loop([latency], 'sensor_latency')
    assert not compound._other_loop([latency], 'temporal_drift')
    assert not compound._other_loop([fx.TemporalDrift((0,), 0.01, 20.0, False)],
                                    'actuator_turn_error')


def test_a_loop_pair_is_tried_only_while_the_closed_loop_is_off():
    assert compound._loop_left(_cmp({'stationary': 1.0, 'closed_loop': 50.0}))
    assert not compound._loop_left(_cmp({'stationary': 50.0, 'closed_loop': 0.1}))
