"""What the named effects leave, and its empirical model (``effects.EmpiricalNoise``): it
closes what no named effect explains, measures a known remainder, and runs in the
closed-loop simulator too."""
import numpy as np

from khepera_noise_ros import effects as fx
from khepera_noise_ros.effects import EmpiricalNoise
from khepera_noise_ros.effects.simulate import EffectEpisodes
from khepera_noise_ros.gap import diagnose
from khepera_noise_ros.simconfig import SimConfig
from khepera_noise_ros.gap.target import Target
from khepera_noise_ros.testing.protocols import (CONFIG, closed_loop_protocol, recorded,
                                                 replayed, stationary_protocol)

OPTIONS = diagnose.Options(config=CONFIG, replicates=60)


def test_the_remainder_says_what_is_off_and_the_empirical_model_closes_it():
    """Per-sensor noise largest at middling levels (no spread law is a hump): the named
    effects leave part of it; the empirical model, fitted on one part, shrinks the
    held-out discrepancy further and loads as an effect."""
    hump = EmpiricalNoise(tuple(range(8)), (0.0, 200.0, 300.0, 525.0),
                          tuple([0.5, 12.0, 12.0, 0.5] * 8))
    result = diagnose.diagnose([recorded(stationary_protocol(samples=40), [hump], seed=5)],
                               OPTIONS)
    rem = result.to_json()['remainder']
    assert rem is not None and 'empirical' in rem
    assert rem['heldout_reduction_with_empirical'] > rem['heldout_reduction_named']
    assert rem['heldout_reduction_with_empirical'] > 0.5
    loaded = fx.loads(fx.dumps([result.empirical]))[0]
    assert loaded == result.empirical
    assert rem['where'] and rem['named_effects'] is not None


def test_the_empirical_model_measures_a_known_remainder():
    hidden = EmpiricalNoise((0, 1, 2), (0.0, 525.0), (6.0, 6.0) * 3)
    rec = recorded(stationary_protocol(samples=60), [hidden], seed=3)
    model = EmpiricalNoise.fit(Target([rec], CONFIG, 1, replicates=20).evidence(None)).effect
    spread = np.asarray(model.spread).reshape(8, -1)
    assert np.all(np.abs(spread[:3] - 6.0) < 2.0), spread[:3]
    assert spread[3:].mean() < 1.5 and spread[3:].max() < 4.0, spread[3:]   # chance only


def test_replay_of_an_empirical_effect_runs_in_the_closed_loop_simulator_too():
    e = EmpiricalNoise(tuple(range(8)), (0.0, 525.0), (3.0, 3.0) * 8)
    rec = replayed(closed_loop_protocol(4), [e], config=SimConfig(), seed=1)
    assert np.isfinite(rec.readings).all()
    EffectEpisodes(effects=[e]).reset(np.arange(3))
