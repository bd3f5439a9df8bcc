"""Each effect of the vocabulary, hidden in small generated data, is named and located.

The 'robot' is the simulator with one effect added (``test_gap_support.recorded``);
the diagnosis gets the recording and the plain simulator's configuration only.
"""
import dataclasses

import pytest

from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.gap import diagnose
from khepera_noise_ros.gap import effects as fx
from test_gap_support import CONFIG, closed_loop_protocol, recorded, stationary_protocol

CASES = [
    (fx.CorrelatedNoise(((1, 2, 3),), 0.02), [[1, 2, 3]], {'strength': (0.02, 0.006)}),
    (fx.IntensityDependentNoise((0, 1, 2, 3, 4, 5), 0.04, 2.0), [0, 1, 2, 3, 4, 5],
     {'exponent': (2.0, 1.0)}),
    (fx.SensorGainOffset((2, 5), (1.12, 0.9), (4.0, -6.0)), [2, 5],
     {'gains': ([1.12, 0.9], 0.02)}),
    (fx.TemporalDrift(tuple(range(8)), 0.012, 30.0, True), list(range(8)),
     {'sd': (0.012, 0.005)}),
    (fx.SensorLatency((0, 1, 2, 3), 1), [0, 1, 2, 3], {'steps': (1, 0)}),
    (fx.SaturationQuantization((0, 5), 0.0, 450.0, 4.0), [0, 5],
     {'high': (450.0, 4.0), 'step': (4.0, 0.0)}),
    (fx.ActuatorTurnError(0.7, 0.1), [], {'scale': (0.7, 0.1)}),
    (fx.SaturationQuantization((0, 1, 2, 3, 4, 5, 6, 7), 0.0, 500.0), list(range(8)),
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
    flicker = fx.IntensityDependentNoise(tuple(range(8)), 0.04, 2.0)
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
    lost = fx.SaturationQuantization((1, 6), dropout=0.02, dropout_value=0.0)
    from test_gap_support import stationary_protocol
    result = diagnose.diagnose([recorded(stationary_protocol(samples=60), [lost], seed=5)],
                               OPTIONS)
    assert result.top_effect == 'saturation_quantization', result.effects[:2]
    top = result.effects[0]
    assert top['sensors'] == [1, 6]
    assert top['parameters']['dropout'] == pytest.approx(0.02, abs=0.01)
    assert top['parameters']['dropout_value'] == 0.0
    assert top['heldout_reduction'] > 0.3
