"""The contract every registered effect keeps, checked for each (as scikit-learn's common
checks check every estimator): it refuses a bad value of any declared parameter with a
one-line ValueError naming the field; it survives its dict, its JSON and the simulator's
params file unchanged; it simulates the same numbers step by step (``start``) as over a
whole run (``over_time``); its fitter finds it again, where and how strong, on a
recording simulated with it; and its name is the emulator's and the docs'.

Each check is a plain function that raises AssertionError saying what is broken; the
last tests show that each one does, on an effect broken on purpose.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import pytest

import numpy as np

from khepera_noise_ros.effects import (NAMES, REGISTRY, VOCABULARY, WORLD_MODEL,
                                       ActuatorResponse, ActuatorTurnError, CorrelatedNoise,
                                       EmpiricalNoise, IntensityDependentNoise, LightResponse,
                                       SaturationQuantization, SensorGainOffset, SensorLatency,
                                       SensorResponse, TemporalDrift)
from khepera_noise_ros.effects.base import Candidate, Effect
from khepera_noise_ros.reality.effects import EFFECTS as EMULATOR_EFFECTS
from khepera_noise_ros.testing.contract import (FitCase, check_fit, check_paths,
                                                check_round_trip, check_validation)

DOCS = Path(__file__).resolve().parents[2] / 'docs'
HUMP = EmpiricalNoise(tuple(range(8)), (0.0, 200.0, 300.0, 525.0),
                      tuple([0.5, 12.0, 12.0, 0.5] * 8))
# typical effects of every registered kind, each form its simulation can take
EXAMPLES = [
    CorrelatedNoise(((1, 2, 3),), 0.02),
    CorrelatedNoise(((3, 5), (0, 6)), 0.01, 4.0),
    IntensityDependentNoise((0, 1, 2, 3, 4, 5), 0.04, 2.0),
    IntensityDependentNoise((0, 2, 7), 0.03, 1.0, 525.0, 1.5, 'bright', False),
    SensorGainOffset((2, 5), (1.12, 0.9), (4.0, -6.0)),
    TemporalDrift(tuple(range(8)), 0.012, 30.0, True),
    TemporalDrift((1, 4), 0.02, 5.0, False),
    ActuatorTurnError(0.7, 0.1),
    ActuatorTurnError(1.2, 0.2, False, 1.5),
    SensorLatency((0, 1, 2, 3), 1),
    SensorLatency((6,), 3),
    SaturationQuantization((0, 5), 0.0, 450.0, 4.0),
    SaturationQuantization((1, 2), 40.0, 500.0, 3.0, 0.05, 0.0, 1.0),
    HUMP,
    EmpiricalNoise((1, 2, 6), (50.0, 300.0), (2.0, 4.0, 1.0, 3.0, 0.5, 5.0),
                   (1.0, 0.0, 0.0, 0.6, 0.8, 0.0, 0.0, 0.0, 1.0), (0.01, 0.0, 0.02), 20.0,
                   (1.0, 0.0, 0.0, 0.5, 0.866, 0.0, 0.3, 0.0, 0.954)),
    LightResponse((1, 2), (-90.0, 0.0, 90.0), (5.0,), (500.0,),
                  (400.0, 300.0, 450.0, 420.0, 200.0, 480.0)),
    LightResponse((4,), (0.0, 90.0), (5.0, 130.0), (500.0, 500.0),
                  (100.0, 480.0, 300.0, 490.0), 'model'),
    ActuatorResponse(3.0, 0.9, 0.25, (3.0, 9.0, 27.0), (0.5, 1.0, 1.1), 0.1, 0.5),
    ActuatorResponse(1.0, 1.1, -0.1, knocks=False),
    SensorResponse((0, 1, 2), 0.6, 0.3, 0.5),
    SensorResponse((3,), 1.4),
]
# the lamp's narrower light on s1 and s2 at the task's knots every 10 degrees
KNOTS = tuple(float(b) for b in np.arange(-180.0, 180.0, 10.0))
OFF = [np.abs((np.array(KNOTS) - axis + 180.0) % 360.0 - 180.0) for axis in (45.0, 10.0)]
NARROW = LightResponse((1, 2), KNOTS, (5.0,), (500.0,), tuple(np.round(np.concatenate(
    [500.0 - 430.0 * np.exp(-np.log(2) * (d / 25.0) ** 2) for d in OFF]), 2)))


def _id(effect: Effect) -> str:
    return f'{effect.name}-{EXAMPLES.index(effect)}'


FIT_CASES = {
    'correlated_noise': FitCase(CorrelatedNoise(((1, 2, 3),), 0.02), False,
                                {'strength': (0.02, 0.006)}),
    'intensity_dependent_noise': FitCase(
        IntensityDependentNoise((0, 1, 2, 3, 4, 5), 0.04, 2.0), False,
        {'exponent': (2.0, 1.0), 'direction': ('dark', 0), 'shared': (True, 0)}),
    'sensor_gain_offset': FitCase(SensorGainOffset((2, 5), (1.12, 0.9), (4.0, -6.0)), False,
                                  {'gains': ((1.12, 0.9), 0.02), 'offsets': ((4.0, -6.0), 4.0)}),
    'temporal_drift': FitCase(TemporalDrift(tuple(range(8)), 0.012, 30.0, True), False,
                              {'sd': (0.012, 0.005), 'shared': (True, 0)}),
    'actuator_turn_error': FitCase(ActuatorTurnError(0.7, 0.1), True,
                                   {'scale': (0.7, 0.1), 'slip': (0.1, 0.1)}),
    'sensor_latency': FitCase(SensorLatency((0, 1, 2, 3), 1), False, {'steps': (1, 0)}),
    'saturation_quantization': FitCase(SaturationQuantization((0, 5), 0.0, 450.0, 4.0), False,
                                       {'high': (450.0, 4.0), 'step': (4.0, 0)}),
    'empirical_noise': FitCase(HUMP, False, {}),
    # their own protocols: a heading sweep every 10 degrees, the closed loop with its
    # headings (the turns measured)
    'light_response': FitCase(NARROW, False, {'sensors': ((1, 2), 0), 'between': ('level', 0)},
                              sweep=10.0),
    'sensor_response': FitCase(SensorResponse(tuple(range(8)), 0.0, 0.4, 0.4), False,
                               {'delay': (0.0, 0.15), 'rate_bright': (0.4, 0.1)}),
    'actuator_response': FitCase(ActuatorResponse(3.0, 0.9, 0.25), True,
                                 {'dead_band': (3.0, 0.3), 'gain': (0.9, 0.05),
                                  'asymmetry': (0.25, 0.05)}, tracked=True),
}


# -- the checks on every registered effect -------------------------------------------------

def test_every_registered_effect_has_examples_and_a_fitting_case():
    assert {e.name for e in EXAMPLES} == set(REGISTRY)
    assert set(FIT_CASES) == set(REGISTRY)
    assert all(type(e) is REGISTRY[e.name] for e in EXAMPLES)


@pytest.mark.parametrize('example', EXAMPLES, ids=_id)
def test_validation(example):
    check_validation(type(example), example)


@pytest.mark.parametrize('example', EXAMPLES, ids=_id)
def test_round_trip(example, tmp_path):
    check_round_trip(type(example), example, tmp_path)


@pytest.mark.parametrize('example', EXAMPLES, ids=_id)
def test_paths(example):
    check_paths(type(example), example)


@pytest.mark.parametrize('name', sorted(FIT_CASES))
def test_fit(name):
    check_fit(REGISTRY[name], FIT_CASES[name])


def test_the_names_are_the_emulators_and_the_docs():
    """The diagnosis's vocabulary is the emulator's effects plus 'none'; the empirical
    model and the world model's parts are registered but no vocabulary names;
    docs/design.md lists the vocabulary."""
    assert set(NAMES) == set(EMULATOR_EFFECTS), (NAMES, EMULATOR_EFFECTS)
    assert VOCABULARY == NAMES + ('none',)
    assert set(REGISTRY) - set(NAMES) == {EmpiricalNoise.name} | set(WORLD_MODEL)
    text = (DOCS / 'design.md').read_text()
    table = text[text.index('**The effect vocabulary**'):]
    table = table[:table.index('\n\n', table.index('| name |'))]
    documented = re.findall(r'^\| `(\w+)` \|', table, flags=re.M)
    assert documented == list(VOCABULARY), documented


# -- each check fails on an effect that breaks it ------------------------------------------

@dataclass(frozen=True)
class Unchecked(SensorLatency):
    """Validates nothing."""
    name: ClassVar[str] = 'unchecked_latency'

    def __post_init__(self) -> None:
        pass


@dataclass(frozen=True)
class Vague(SensorLatency):
    """Refuses a bad value without saying which field."""
    name: ClassVar[str] = 'vague_latency'

    def __post_init__(self) -> None:
        try:
            super().__post_init__()
        except ValueError:
            raise ValueError('bad value') from None


@dataclass(frozen=True)
class Rambling(SensorLatency):
    """Names the field, over two lines."""
    name: ClassVar[str] = 'rambling_latency'

    def __post_init__(self) -> None:
        try:
            super().__post_init__()
        except ValueError as exc:
            raise ValueError(f'{exc}\nsee the docs') from None


@dataclass(frozen=True)
class Lossy(SensorLatency):
    """Its dict form leaves the delay out."""
    name: ClassVar[str] = 'lossy_latency'

    def to_dict(self) -> dict[str, Any]:
        out = super().to_dict()
        del out['steps']
        return out


@dataclass(frozen=True)
class Rounded(TemporalDrift):
    """Its dict form rounds the size of the wander."""
    name: ClassVar[str] = 'rounded_drift'

    def to_dict(self) -> dict[str, Any]:
        return dict(super().to_dict(), sd=round(self.sd, 2))


@dataclass(frozen=True)
class Shifted(SensorGainOffset):
    """Its whole-run path adds half a reading."""
    name: ClassVar[str] = 'shifted_gain_offset'

    def over_time(self, level, rng):
        return super().over_time(level, rng) + 0.5


@dataclass(frozen=True)
class Redrawn(CorrelatedNoise):
    """Its whole-run path draws the samples in another order."""
    name: ClassVar[str] = 'redrawn_noise'

    def over_time(self, level, rng):
        flipped = level[::-1].copy()
        return super().over_time(flipped, rng)[::-1]


@dataclass(frozen=True)
class Misfit(SensorLatency):
    """Its fitter finds the right sensors and the wrong delay."""
    name: ClassVar[str] = 'misfit_latency'

    @classmethod
    def fit(cls, evidence):
        cand = SensorLatency.fit.__func__(cls, evidence)
        return Candidate(cls.name, cls(cand.effect.sensors, cand.effect.steps + 1), cand.note)


@dataclass(frozen=True)
class Blind(SensorLatency):
    """Its fitter never finds anything."""
    name: ClassVar[str] = 'blind_latency'

    @classmethod
    def fit(cls, evidence):
        return Candidate(cls.name, None, 'nothing to see')


@pytest.mark.parametrize('broken, why', [
    (Unchecked, 'accepted'), (Vague, 'does not name the field'), (Rambling, 'not one line')])
def test_the_validation_check_fails_on_bad_validation(broken, why):
    with pytest.raises(AssertionError, match=why):
        check_validation(broken, broken((0, 1), 2))


@pytest.mark.parametrize('broken, example', [
    (Lossy, Lossy((0, 1), 2)), (Rounded, Rounded((0, 3), 0.0123, 12.0, False))])
def test_the_round_trip_check_fails_on_a_lossy_dict(broken, example, monkeypatch, tmp_path):
    monkeypatch.setitem(REGISTRY, broken.name, broken)
    with pytest.raises(AssertionError, match='round trip'):
        check_round_trip(broken, example, tmp_path)


@pytest.mark.parametrize('broken, example', [
    (Shifted, Shifted((2, 5), (1.12, 0.9), (4.0, -6.0))),
    (Redrawn, Redrawn(((1, 2, 3),), 0.02))])
def test_the_paths_check_fails_when_over_time_differs_from_start(broken, example):
    with pytest.raises(AssertionError, match='start and over_time differ'):
        check_paths(broken, example)


@pytest.mark.parametrize('broken, why', [(Misfit, 'steps 2, not 1'), (Blind, 'the fit gave None')])
def test_the_fit_check_fails_on_a_fitter_with_wrong_answers(broken, why):
    with pytest.raises(AssertionError, match=why):
        check_fit(broken, FitCase(broken((0, 1, 2, 3), 1), False, {'steps': (1, 0)}))
