"""The simulator with effects (``effects.simulate``): the core's episodes when there are none,
effects with memory across a new noise model, the converter saturating once at the end,
each effect's whole-run path in the cases it shortcuts, and the draws a ``SimCache``
remembers being the generator's own."""
import numpy as np
import pytest

from khepera_noise_ros.core import network, task
from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.core.streams import UNIT
from khepera_noise_ros.effects import (IntensityDependentNoise, SensorGainOffset,
                                       SensorLatency, TemporalDrift)
from khepera_noise_ros.effects.simulate import EffectEpisodes, sense, stationary
from khepera_noise_ros.testing.protocols import GENOME

NOISE = NoiseModel.independent_only(0.02)
RAISED = SensorGainOffset((0, 1, 2, 3, 4, 5, 6, 7), (1.0,) * 8, (20.0,) * 8)


def _run(env, seeds) -> np.ndarray:
    weights = network.unpack(np.repeat(np.array(GENOME)[None], len(seeds), axis=0))
    out, readings = [], env.reset(seeds)
    while readings is not None:
        out.append(readings.copy())
        readings = env.step(*network.act(weights, readings))
    return np.stack(out)


def _still(env, seeds) -> np.ndarray:
    """Readings of robots that never turn (the heading changes only by the knocks)."""
    out, readings = [], env.reset(seeds)
    while readings is not None:
        out.append(readings.copy())
        readings = env.step(np.ones(len(seeds), int), np.zeros(len(seeds), int))
    return np.stack(out)


# -- episodes ---------------------------------------------------------------------------

def test_without_effects_the_episodes_are_the_cores():
    seeds = np.arange(6)
    assert np.array_equal(_run(EffectEpisodes(), seeds), _run(task.Episodes(), seeds))


def test_latency_delays_readings_and_survives_a_new_noise_model():
    seeds = np.arange(3)
    plain = _still(task.Episodes(noise=NoiseModel('none')), seeds)
    env = EffectEpisodes(noise=NoiseModel('none'), effects=(SensorLatency((0, 1), 1),))
    env.reset(seeds)
    env.noise = NoiseModel('none')                 # as a node does on a parameter change
    assert len(env.noise.reading) == 1
    lagged = _still(env, seeds)
    assert np.array_equal(lagged[1:, :, :2], plain[:-1, :, :2])      # one step late
    assert np.array_equal(lagged[0, :, :2], plain[0, :, :2])         # the first repeats
    assert np.array_equal(lagged[:, :, 2:], plain[:, :, 2:])


# -- the converter saturates once -------------------------------------------------------

def test_a_level_beyond_the_range_saturates_the_reading_in_a_stationary_run():
    """Light at 520 raised by 20 (an offset) is 540 before the noise of +-2% (at most
    11): every reading is the converter's end, 525, at either rounding."""
    base = np.full((400, 8, 3), 520.0)
    for rounding in ('level', 'reading'):
        noise = NoiseModel.independent_only(0.02, rounding=rounding)
        out = stationary(base, noise, [RAISED], seed=4)
        assert np.all(out == 525.0), (rounding, np.unique(out))
    # below the end nothing changes: the offset and the noise as before
    low = stationary(np.full((400, 8, 3), 300.0), NOISE, [RAISED], seed=4)
    assert low.min() < 320.0 < low.max() and np.all(np.abs(low - 320.0) <= 7.0)


def test_a_level_beyond_the_range_saturates_the_reading_in_closed_loop_sensing():
    """The same through the episodes' sensing (``sense``: the closed loop, the node)."""
    rng = np.random.default_rng(0)
    draws = rng.integers(0, int(UNIT) + 1, size=(8, 500), dtype=np.uint16)
    light = [RAISED.start(500, 8, rng)]
    out = sense(np.full((8, 500), 520.0), NOISE, draws, draws[:1], light, [])
    assert np.all(out == 525.0), np.unique(out)


# -- whole runs at once ------------------------------------------------------------------

@pytest.mark.parametrize('steps', [0, 1, 2, 5, 40])
@pytest.mark.parametrize('sensors', [(1, 4), tuple(range(8))])
def test_latency_over_time_is_the_late_sample(steps, sensors):
    level = np.random.default_rng(steps).normal(size=(30, 8, 3))
    out = SensorLatency(sensors, steps).over_time(level, np.random.default_rng(0))
    late = np.maximum(np.arange(30) - steps, 0)
    plain = level.copy()
    plain[:, list(sensors)] = level[late][:, list(sensors)]
    assert np.array_equal(out, plain)


@pytest.mark.parametrize('held', [True, False])
def test_intensity_over_time_equals_the_law_at_every_sample(held):
    rng = np.random.default_rng(5)
    level = rng.uniform(0, 525, size=(90, 8, 4))
    if held:                  # runs of 30 samples at one light level, as a replay's light
        level = np.repeat(level[::30], 30, axis=0)
    effect = IntensityDependentNoise((0, 2, 5), 0.04, 2.5, constant=0.5, shared=False)
    out = effect.over_time(level, np.random.default_rng(1))
    z = np.random.default_rng(1).standard_normal((90, 3, 4))
    plain = level.copy()
    plain[:, [0, 2, 5]] += z * effect.amplitude(level[:, [0, 2, 5]])
    assert np.array_equal(out, plain)


def test_a_drift_over_time_has_its_sd_and_correlation_time():
    drift = TemporalDrift((0,), 0.05, 10.0, True)
    flat = np.full((20000, 8, 1), 100.0)
    out = drift.over_time(flat, np.random.default_rng(1))[:, 0, 0] / 100.0 - 1.0
    assert abs(out.std() - 0.05) < 0.01
    lag1 = np.corrcoef(out[:-1], out[1:])[0, 1]
    assert abs(lag1 - np.exp(-0.1)) < 0.03


def test_drift_on_every_sensor_in_place_equals_the_gathered_columns():
    level = np.random.default_rng(4).uniform(50, 500, (120, 8, 3))
    for shared in (True, False):
        drift = TemporalDrift(tuple(range(8)), 0.02, 12.0, shared)
        out = drift.over_time(level, np.random.default_rng(9))
        rng = np.random.default_rng(9)
        z = rng.standard_normal((120, 1 if shared else 8, 3))
        a = np.exp(-1.0 / 12.0)
        z[0] *= 0.02
        z[1:] *= np.sqrt(1 - a * a) * 0.02
        state = np.zeros_like(z)
        state[0] = z[0]
        for t in range(1, 120):
            state[t] = a * state[t - 1] + z[t]
        plain = level.copy()
        plain[:, list(range(8))] *= 1.0 + state
        assert np.allclose(out, plain, rtol=1e-12, atol=0)
        reordered = TemporalDrift(tuple(range(7, -1, -1)), 0.02, 12.0, shared)
        back = reordered.over_time(level, np.random.default_rng(9))
        plain = level.copy()
        plain[:, list(range(7, -1, -1))] *= 1.0 + state
        assert np.allclose(back, plain, rtol=1e-12, atol=0)
