"""Slow change over time (``temporal_drift``): a change shared by all sensors that moves in
steps is a drift, not a calibration; each sensor's own drift beside a much larger shared
flicker is found by the drift's fitter; and its search in the box the own wanders bound
stops within the objective's own noise.

The robot is the blind benchmark's emulated robot with no effects (the room's light then
changes in steps between episodes) or the simulator with hidden effects.
"""
import numpy as np

from khepera_noise_ros.effects import (IntensityDependentNoise, SensorGainOffset,
                                       TemporalDrift, temporal_drift)
from khepera_noise_ros.gap import diagnose
from khepera_noise_ros.gap.target import Target
from khepera_noise_ros.testing.protocols import (CONFIG, recorded, replayed,
                                                 stationary_protocol)

OPTIONS = diagnose.Options(config=CONFIG, replicates=100, compound=False, remainder=False)
FLICKER = IntensityDependentNoise(tuple(range(8)), 0.06, 2.0, 525.0, 0.0, 'dark', True)
DRIFTING = (0, 2, 3, 5, 6)
DRIFT = TemporalDrift(DRIFTING, 0.01, 40.0, False)


def _changed(rec, gain):
    """``rec`` with every reading scaled by ``gain`` (per sample), as the robot reads."""
    out = rec.select(np.ones(len(rec), bool))
    out.readings = np.clip(np.round(rec.readings * gain[:, None]), 0, 525)
    return out


def _steps(rec, steps: dict):
    """A shared step change: from episode e on, readings scaled by 1 + ``steps[e]`` more
    (negative: the room brighter, the Khepera reads lower)."""
    return 1.0 + sum(size * (rec.episode >= e) for e, size in steps.items())


def test_a_shared_two_step_change_is_answered_temporal_drift(clean_robot):
    real = _changed(clean_robot, _steps(clean_robot, {1: -0.06, 3: 0.02}))
    result = diagnose.diagnose([real], OPTIONS)
    assert result.top_effect == 'temporal_drift', result.effects[:2]
    top = result.effects[0]
    assert top['sensors'] == list(range(8))
    assert top['parameters']['shared'] is True
    assert 'move together over time' in top['note']
    gain = next(e for e in result.effects if e['name'] == 'sensor_gain_offset')
    assert gain['sensors'] == [], gain['note']


def test_a_true_per_sensor_offset_is_still_a_gain_offset(clean_robot):
    """Offsets on two sensors, constant in time: no shared change over time."""
    offset = SensorGainOffset((2, 5), (1.0, 1.0), (10.0, -10.0))
    real = replayed(clean_robot, [offset], seed=4)
    result = diagnose.diagnose([real], OPTIONS)
    assert result.top_effect == 'sensor_gain_offset', result.effects[:2]
    assert result.effects[0]['sensors'] == [2, 5]


def _given_flicker():
    rec = recorded(stationary_protocol(samples=120), [DRIFT, FLICKER], seed=11)
    return Target([rec], CONFIG, 3, 'auto', replicates=40).with_given([FLICKER])


def test_the_drift_fitter_finds_each_sensors_wander_given_the_flicker():
    target = _given_flicker()
    cand = TemporalDrift.fit(target.evidence(target.compare(replicates=40)))
    assert cand.effect is not None, cand.note
    assert set(cand.effect.sensors) >= set(DRIFTING), cand.note
    assert not cand.effect.shared
    assert 0.5 * DRIFT.sd < cand.effect.sd < 2.0 * DRIFT.sd, cand.effect


def test_drift_search_in_the_own_wander_box_stops_within_the_objectives_noise(monkeypatch):
    """10 objectives where the own wander bounds the search: the answer's objective lies
    within the objective's spread between simulator seeds of the 16-objective answer's."""
    t = _given_flicker()
    c = t.compare(replicates=40)
    asked = []
    plain = temporal_drift.minimize
    monkeypatch.setattr(temporal_drift, 'minimize', lambda f, x0, **kw: asked.append(
        kw['options']['maxfev']) or plain(f, x0, **kw))
    short = TemporalDrift.fit(t.evidence(c))
    monkeypatch.setattr(temporal_drift, 'EVALUATIONS', (16, 16))
    full = TemporalDrift.fit(t.evidence(c))
    assert asked == [10, 16] and short.effect is not None and full.effect is not None
    spread = [t.with_seed(t.seed + 1000 * k).objective([full.effect]) for k in range(1, 5)]
    assert abs(t.objective([short.effect]) - t.objective([full.effect])) <= np.std(spread)
