"""`khepera-noise fit` (``experiment.noisefit``): the paper's model recovered from recordings of
known noise."""
import pytest

from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.effects import IntensityDependentNoise
from khepera_noise_ros.experiment import noisefit
from khepera_noise_ros.simconfig import SimConfig
from khepera_noise_ros.testing.protocols import recorded, stationary_protocol


def test_groups_levels_and_distribution_of_the_paper_model_are_recovered():
    truth = NoiseModel('combination', 0.04, 0.02, ((0, 1, 2), (3, 4, 5), (6, 7)), 'normal')
    rec = recorded(stationary_protocol(samples=20), config=SimConfig(noise=truth))
    fitted = noisefit.fit(rec, level_dependence=False)
    assert fitted.groups == [[0, 1, 2], [3, 4, 5], [6, 7]]
    assert fitted.dependent == pytest.approx(0.04, abs=0.006)
    assert fitted.independent == pytest.approx(0.02, abs=0.004)
    assert fitted.distribution == 'normal'
    assert fitted.noise_model().model == 'combination'
    assert {row['condition'] for row in fitted.by_condition} == set(rec.conditions())


def test_independent_noise_gives_no_groups():
    noise = NoiseModel.independent_only(0.03, distribution='uniform')
    rec = recorded(stationary_protocol(samples=20), config=SimConfig(noise=noise))
    fitted = noisefit.fit(rec, level_dependence=False)
    assert fitted.groups == []
    assert fitted.noise_model().model == 'independent'
    assert fitted.independent == pytest.approx(0.03, abs=0.005)
    assert fitted.distribution == 'uniform'


def test_noise_that_grows_with_the_level_is_found_where_the_data_show_it():
    flicker = IntensityDependentNoise(tuple(range(8)), 0.05, 2.0)
    rec = recorded(stationary_protocol(samples=20), (flicker,))
    fitted = noisefit.fit(rec)
    assert [e.name for e in fitted.effects] == ['intensity_dependent_noise']
    assert fitted.effects[0].exponent >= 1.0
    assert any('level dependence: the data show' in note for note in fitted.notes)
