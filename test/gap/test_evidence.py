"""The measurements that locate an effect (``gap.evidence``): the sensors whose own part
wanders beside a far larger shared flicker, and a change over time shared by all
sensors, real recordings against their replays."""
import numpy as np
import pytest

from khepera_noise_ros.effects import IntensityDependentNoise, TemporalDrift
from khepera_noise_ros.gap import evidence, split
from khepera_noise_ros.testing.protocols import recorded, replayed, stationary_protocol

FLICKER = IntensityDependentNoise(tuple(range(8)), 0.06, 2.0, 525.0, 0.0, 'dark', True)
DRIFTING = (0, 2, 3, 5, 6)
DRIFT = TemporalDrift(DRIFTING, 0.01, 40.0, False)


# -- own wanders --------------------------------------------------------------------------

@pytest.fixture(scope='module')
def protocol():
    return stationary_protocol(samples=120)


def _wandering(rec, given, seed=7):
    """The sensors whose own part wanders more than in two replays with ``given``."""
    sim = replayed(rec, given, seed=seed, copies=2)

    def parts(shared_by):
        return [evidence.Own(rec).parts(shared_by)], [evidence.Own(sim).parts(shared_by)]
    return evidence.wandering(parts, rec.channels_used)


def test_each_sensors_own_drift_shows_beside_a_shared_flicker(protocol):
    rec = recorded(protocol, [DRIFT, FLICKER], seed=11)
    found = _wandering(rec, [FLICKER])
    assert set(found) == set(DRIFTING), {s: round(v['z'], 1) for s, v in found.items()}
    for v in found.values():
        assert 0.3 * DRIFT.sd < v['sd'] < 2.0 * DRIFT.sd, v


def test_a_shared_flicker_alone_is_no_wander(protocol):
    for seed in (11, 12):
        rec = recorded(protocol, [FLICKER], seed=seed)
        assert _wandering(rec, []) == {}          # not even without the flicker simulated
        assert _wandering(rec, [FLICKER]) == {}


def test_steady_sensors_beside_strongly_drifting_ones_are_not_called_wandering(protocol):
    """The mean of the other sensors carries their wanders into a steady sensor's own
    part; the shared part is then taken from the steady sensors alone."""
    strong = TemporalDrift((0, 1, 2, 3), 0.04, 40.0, False)
    rec = recorded(protocol, [strong, FLICKER], seed=13)
    found = _wandering(rec, [FLICKER])
    assert set(found) == {0, 1, 2, 3}, {s: round(v['z'], 1) for s, v in found.items()}


# -- a change shared over time ------------------------------------------------------------

def _changed(rec, gain):
    """``rec`` with every reading scaled by ``gain`` (per sample), as the robot reads."""
    out = rec.select(np.ones(len(rec), bool))
    out.readings = np.clip(np.round(rec.readings * gain[:, None]), 0, 525)
    return out


def _steps(rec, steps: dict):
    """A shared step change: from episode e on, readings scaled by 1 + ``steps[e]`` more."""
    return 1.0 + sum(size * (rec.episode >= e) for e, size in steps.items())


@pytest.mark.parametrize('shape', ['steps', 'ramp', 'sine', 'none'])
def test_the_time_signature_of_shared_changes(clean_robot, shape):
    """Steps, a ramp and a slow wave shared by all sensors show as shared factors that
    vary over the runs more than the simulator's; the unchanged robot does not."""
    clean = clean_robot
    t = np.arange(len(clean)) / len(clean)
    gain = {'steps': _steps(clean, {2: -0.04, 6: 0.03}), 'ramp': 1.0 + 0.08 * (t - 0.5),
            'sine': 1.0 + 0.03 * np.sin(2 * np.pi * 1.5 * t), 'none': np.ones(len(clean))}
    real = _changed(clean, gain[shape])
    fit = real.select(split.by_episode(real)[0])
    change = evidence.shared_change([fit], [replayed(fit, seed=2, copies=2)], list(range(8)))
    assert change['significant'] == (shape != 'none'), change['p_value']
    if shape != 'none':
        assert change['sd'] > 0.005
    # with each run divided by its shared factor, no change is left
    steady = fit.readings.astype(np.float64)
    for r, f in change['runs'][0]:
        steady[r] = steady[r] / f
    fit.readings = steady
    again = evidence.shared_change([fit], [replayed(fit, seed=2, copies=2)], list(range(8)))
    assert not again['significant']
