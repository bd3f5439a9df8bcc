"""Each effect of the vocabulary, hidden in small generated data, is named and located.

The 'robot' is the simulator with one effect added (``testing.protocols.recorded``);
the diagnosis gets the recording and the plain simulator's configuration only.
"""
import dataclasses

import pytest

from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.effects import (ActuatorTurnError, CorrelatedNoise,
                                       IntensityDependentNoise, SaturationQuantization,
                                       SensorGainOffset, SensorLatency, TemporalDrift)
from khepera_noise_ros.gap import diagnose
from khepera_noise_ros.testing.protocols import (CONFIG, closed_loop_protocol, recorded,
                                                 stationary_protocol)

CASES = [
    (CorrelatedNoise(((1, 2, 3),), 0.02), [[1, 2, 3]], {'strength': (0.02, 0.006)}),
    (IntensityDependentNoise((0, 1, 2, 3, 4, 5), 0.04, 2.0), [0, 1, 2, 3, 4, 5],
     {'exponent': (2.0, 1.0)}),
    (SensorGainOffset((2, 5), (1.12, 0.9), (4.0, -6.0)), [2, 5],
     {'gains': ([1.12, 0.9], 0.02)}),
    (TemporalDrift(tuple(range(8)), 0.012, 30.0, True), list(range(8)),
     {'sd': (0.012, 0.005)}),
    (SensorLatency((0, 1, 2, 3), 1), [0, 1, 2, 3], {'steps': (1, 0)}),
    (SaturationQuantization((0, 5), 0.0, 450.0, 4.0), [0, 5],
     {'high': (450.0, 4.0), 'step': (4.0, 0.0)}),
    (ActuatorTurnError(0.7, 0.1), [], {'scale': (0.7, 0.1)}),
    (SaturationQuantization((0, 1, 2, 3, 4, 5, 6, 7), 0.0, 500.0), list(range(8)),
     {'high': (500.0, 4.0)}),
]
OPTIONS = diagnose.Options(config=CONFIG, replicates=40)


def recordings(effects):
    """What a robot with ``effects`` records: turns need the closed loop, the rest do not."""
    if any(e.name == 'actuator_turn_error' for e in effects):
        return [recorded(closed_loop_protocol(16), effects, seed=6)]
    return [recorded(stationary_protocol(samples=20), effects, seed=5)]


@pytest.mark.parametrize('effect, location, parameters', CASES, ids=lambda c: getattr(
    c, 'name', ''))
def test_the_hidden_effect_is_named_located_and_shrinks_the_gap(effect, location, parameters):
    result = diagnose.diagnose(recordings([effect]), OPTIONS)
    assert result.gap_significant
    assert result.top_effect == effect.name, result.effects[:2]
    top = result.effects[0]
    found = top['parameters']['groups'] if effect.name == 'correlated_noise' else top['sensors']
    assert found == location
    assert top['heldout_reduction'] > 0.8
    assert top['discrepancy_after'] < top['discrepancy_before'] / 5
    for name, (value, tolerance) in parameters.items():
        assert top['parameters'][name] == pytest.approx(value, abs=tolerance), name


def test_no_effect_means_no_significant_gap_and_the_answer_none():
    result = diagnose.diagnose(recordings([]), OPTIONS)
    assert not result.gap_significant
    assert result.top_effect == 'none'
    assert result.fitted is None
    assert any('not significant' in note for note in result.notes)
    assert result.to_json()['top_effect'] == 'none'


def test_a_gap_no_effect_explains_is_answered_none_with_the_reason():
    """The robot is quieter than the simulator (1% noise, not 2%): a significant gap, but
    every candidate effect only adds noise, so none can explain it."""
    quiet = dataclasses.replace(CONFIG, noise=NoiseModel.independent_only(0.01))
    real = [recorded(stationary_protocol(samples=20), (), config=quiet, seed=5)]
    result = diagnose.diagnose(real, OPTIONS)
    assert result.gap_significant
    assert result.where[0]['statistic'] == 'spread'
    assert result.where[0]['real'] < result.where[0]['sim']
    assert result.top_effect == 'none'
    assert any('no effect explains' in note for note in result.notes)


def test_an_effect_fitted_in_bright_light_shrinks_the_gap_in_dim_light():
    """Flicker that grows steeply with darkness, fitted with the dim condition withheld:
    the level dependence must carry over to the condition the fit never saw."""
    flicker = IntensityDependentNoise(tuple(range(8)), 0.04, 2.0)
    real = recordings([flicker])
    options = dataclasses.replace(OPTIONS, held_out=('bulb_2ft',))
    result = diagnose.diagnose(real, options)
    assert result.top_effect == 'intensity_dependent_noise'
    assert result.effects[0]['heldout_reduction'] > 0.8
    assert {k.condition for k in result.held_out_after.keys} <= {'bulb_2ft', None}
    shared = next(e for e in result.effects if e['name'] == 'correlated_noise')
    assert shared['heldout_reduction'] < result.effects[0]['heldout_reduction'] - 0.2


def test_isolated_dropouts_to_zero_are_found_located_and_measured():
    """Two sensors lose 2% of their readings (they read 0): rare events, so a longer
    recording; the spread they add is named as dropouts, not as noise."""
    lost = SaturationQuantization((1, 6), dropout=0.02, dropout_value=0.0)
    result = diagnose.diagnose([recorded(stationary_protocol(samples=60), [lost], seed=5)],
                               OPTIONS)
    assert result.top_effect == 'saturation_quantization', result.effects[:2]
    top = result.effects[0]
    assert top['sensors'] == [1, 6]
    assert top['parameters']['dropout'] == pytest.approx(0.02, abs=0.01)
    assert top['parameters']['dropout_value'] == 0.0
    assert top['heldout_reduction'] > 0.3


def test_a_spread_law_growing_with_brightness_is_fitted_with_its_parameters():
    """The flicker of the vocabulary grows with darkness; this noise grows with
    brightness, per sensor, with a constant part: the law's direction, power and
    constant come out, and it removes most of the held-out gap."""
    law = IntensityDependentNoise(tuple(range(8)), 0.03, 1.0, 525.0, 1.5, 'bright', False)
    result = diagnose.diagnose([recorded(stationary_protocol(samples=40), [law], seed=5)],
                               dataclasses.replace(OPTIONS, replicates=60))
    assert result.top_effect == 'intensity_dependent_noise', result.effects[:2]
    p = result.effects[0]['parameters']
    assert p['direction'] == 'bright' and not p['shared']
    assert abs(p['exponent'] - 1.0) <= 0.5 and p['constant'] < 4.0
    assert result.effects[0]['heldout_reduction'] > 0.8


def test_shared_noise_of_a_fixed_size_is_correlated_noise_in_every_group():
    """Two non-adjacent pairs share noise of 6 readings whatever the light (a supply):
    both groups are found and the fixed size is fitted."""
    hidden = [CorrelatedNoise(((3, 5), (0, 6)), 0.0, 6.0)]
    result = diagnose.diagnose([recorded(stationary_protocol(samples=30), hidden, seed=5)],
                               dataclasses.replace(OPTIONS, replicates=60))
    assert result.top_effect == 'correlated_noise', result.effects[:2]
    p = result.effects[0]['parameters']
    assert sorted(map(sorted, p['groups'])) == [[0, 6], [3, 5]]
    assert abs(p['constant'] - 6.0) < 1.5 and p['strength'] < 0.005
