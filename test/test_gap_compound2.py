"""Compound selection: the set chosen when one effect dominates, and between nested models.

The 'robot' is the emulated one (``reality``) with two effects set, recorded as
``benchmark/blind_gap.py`` records its stationary protocol; the diagnosis sees
only the recording and the paper's independent model at the robot's noise level.
"""
import sys
from pathlib import Path

import numpy as np
import pytest

from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.gap import compound, diagnose
from khepera_noise_ros.simconfig import SimConfig

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'benchmark'))
from blind_gap import STATIONARY, record_stationary, robot  # noqa: E402
from khepera_noise_ros.reality.effects import EffectsConfig  # noqa: E402

OPTIONS = diagnose.Options(config=SimConfig(noise=NoiseModel.independent_only(0.02)),
                           replicates=100, remainder=False)
ALL = tuple(range(8))


def _chosen(config: EffectsConfig, seed: int = 1) -> list:
    recording = record_stationary(robot(config, seed), STATIONARY, samples=60)
    return diagnose.diagnose([recording], OPTIONS).to_json()['compound']['chosen']


def test_a_drift_beside_a_large_latency_is_kept():
    """A two-sample latency makes 99% of the gap (the step responses); the drift's share
    of the whole is small, but the level and autocorrelation families, which the latency
    does not touch, carry it.  It is a wander of each sensor's own, as the robot's: the
    run-to-run levels also move together a little (the mean of eight wanders), and
    fitted as one change shared by all it left each sensor's own autocorrelation
    unexplained, where a spread law then stood in (``gap.fitdrift`` fits both)."""
    config = EffectsConfig.none(0.02).only(
        'sensor_latency', 'temporal_drift',
        sensor_latency={'strength': 2, 'location': ALL},
        temporal_drift={'strength': 0.019, 'time_constant': 49.0, 'shared': False,
                        'location': ALL})
    chosen = _chosen(config)
    assert [c['name'] for c in chosen] == ['sensor_latency', 'temporal_drift'], chosen
    assert chosen[1]['added_reduction'] < 0.02
    assert not chosen[1]['parameters']['shared']
    assert 0.5 * 0.019 < chosen[1]['parameters']['sd'] < 2 * 0.019, chosen[1]


def test_group_noise_beside_a_calibration_is_a_group_not_a_spread_law():
    """Noise shared by two sensors, sd a share of their level, is a spread law of
    exponent 0 with one shared draw too; with one more free parameter the law must not
    win by chance: the simpler effect that explains the held-out data as well is chosen."""
    config = EffectsConfig.none(0.02).only(
        'sensor_gain_offset', 'correlated_noise',
        sensor_gain_offset={'gains': (1, 1, 1, 0.8, 1, 1, 1, 1), 'offsets': (0.0,) * 8,
                            'location': (3,)},
        correlated_noise={'strength': 0.027, 'location': ((6, 7),)})
    chosen = _chosen(config)
    assert [c['name'] for c in chosen] == ['sensor_gain_offset', 'correlated_noise'], chosen
    assert chosen[1]['parameters']['groups'] == [[6, 7]]
    assert chosen[1]['counted_by'].endswith('simpler')


@pytest.mark.parametrize('family, left, expected', [
    (0.2, 0.2, 'family'),        # a tenth of a family's own, and of all that is left
    (0.2, 0.05, ''),             # a sliver of what is left: not enough
    (0.05, 0.5, ''),             # too small a share of any family's own
])
def test_a_step_counts_by_a_familys_share_only_when_confirmed(family, left, expected):
    d_prev = 100.0
    d_new = d_prev * (1 - left)
    calls = []
    rule = compound._counts(0.001, (0.001, 0.2), 0.01, d_new, d_prev, lambda: False,
                            family, lambda: calls.append(1) or True)
    assert rule == expected
    # not confirmed on the second simulator seed: does not count
    assert compound._counts(0.001, (0.001, 0.2), 0.01, d_new, d_prev, lambda: False,
                            family, lambda: False) == ''
    # large shares still count by the old rules, named
    assert compound._counts(0.01, (0.0, 0.0), 0.01, 90.0, 100.0, lambda: False) == 'min_added'
    assert compound._counts(0.001, (0.2, 0.0), 0.01, 90.0, 100.0, lambda: False) == 'min_local'
    assert compound._counts(0.01, (0.0, 0.0), 0.2, 90.0, 100.0, lambda: False) == ''


def test_a_calibration_alone_is_not_padded_with_a_drift():
    """Three sensors off in gain and offset, nothing else: a per-sensor drift fitted
    beside the calibration lowered the held-out discrepancy only by widening the
    simulated levels' error bars (the held-out levels a little off the fitted line)."""
    config = EffectsConfig.none(0.02).only(
        'sensor_gain_offset',
        sensor_gain_offset={'gains': (0.938, 1, 1, 1, 1, 1.155, 0.931, 1),
                            'offsets': (3.05, 0, 0, 0, 0, 8.88, 7.3, 0),
                            'location': (0, 5, 6)})
    chosen = _chosen(config, seed=3)
    assert [c['name'] for c in chosen] == ['sensor_gain_offset'], chosen
    assert chosen[0]['sensors'] == [0, 5, 6]


def test_closer_judges_a_step_at_the_error_bars_before_it():
    from khepera_noise_ros.gap.statistics import Key
    from khepera_noise_ros.gap.where import Comparison
    keys = [Key('level', (0,), 'task', None), Key('level', (1,), 'task', None)]

    def cmp(sim, se):
        real, sim, se = np.array([10.0, 5.0]), np.array(sim), np.array(se)
        return Comparison(keys, real, sim, se, (real - sim) / se)
    current = cmp([0.0, 5.0], [1.0, 1.0])
    wider = cmp([0.0, 5.0], [10.0, 1.0])          # the same simulated levels, wider bars
    assert wider.discrepancy < current.discrepancy
    assert not compound._closer(current, wider)
    assert compound._closer(current, cmp([9.0, 5.0], [1.0, 1.0]))
