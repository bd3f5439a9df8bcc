"""The outside blind generator injects what it says it injects (not the diagnosis's score).

These tests live beside the generator (kept outside the package on purpose) and are
collected by the suite through setup.cfg's ``testpaths``."""
import numpy as np
import pytest

from khepera_noise_ros.core.khepera import SENSOR_ANGLES_DEG, World

from . import robot
from .cases import NAMES, draw_cases
from .record import make_recording
from .score import score_case
from .shapes import Drift, Groups, Latency, Limit, Spread, TurnError

pytestmark = pytest.mark.filterwarnings('error::RuntimeWarning')

HEADINGS = (0.0, 30.0)


def _pair(seed, effects):
    rng = np.random.default_rng(seed)
    return robot.stationary(seed, effects, HEADINGS, 60, rng)


def _residuals(rec):
    """Readings minus each episode's mean: the fast part."""
    r = rec.readings.copy()
    for e in np.unique(rec.episode):
        m = rec.episode == e
        r[m] -= r[m].mean(axis=0)
    return r


def _corr(rec, a, b, condition):
    r = _residuals(rec)[rec.condition == condition]
    return float(np.corrcoef(r[:, a], r[:, b])[0, 1])


def test_cases_are_deterministic_for_a_seed_and_cover_the_vocabulary():
    a = [[e.describe() for e in c['effects']] for c in draw_cases(4, 14, 6, 2)]
    b = [[e.describe() for e in c['effects']] for c in draw_cases(4, 14, 6, 2)]
    c = [[e.describe() for e in c['effects']] for c in draw_cases(5, 14, 6, 2)]
    assert a == b and a != c
    cases = draw_cases(4, 14, 6, 2)
    singles = [c['effects'][0].name for c in cases if c['kind'] == 'single']
    assert set(singles) == set(NAMES)
    compounds = [c for c in cases if c['kind'] == 'compound']
    assert all(2 <= len(c['effects']) <= 4 for c in compounds)
    assert [c['protocol'] for c in compounds] == ['stationary', 'closed_loop'] * 3
    assert all(len({e.name for e in c['effects']}) == len(c['effects']) for c in compounds)
    for c in cases:
        closed = any(e.name in ('sensor_latency', 'actuator_turn_error') for e in c['effects'])
        assert c['protocol'] == ('closed_loop' if closed else 'stationary')


def test_a_non_adjacent_pair_group_raises_that_pairs_correlation_only():
    # s0 and s6 are in different groups of the simulator's own shared noise
    effect = Groups('nonadjacent_pairs', [0, 6], groups=[[0, 6]], sd=[15.0],
                    weights=[[1.0, 1.0]])
    clean, real = _pair(1, [effect])
    before, after = _corr(clean, 0, 6, 'room_dark'), _corr(real, 0, 6, 'room_dark')
    assert abs(before) < 0.3 and after > before + 0.3
    assert abs(_corr(real, 1, 7, 'room_dark') - _corr(clean, 1, 7, 'room_dark')) < 0.15


def test_a_spread_growing_with_darkness_adds_more_spread_in_the_dark():
    effect = Spread('dark_power', list(range(8)), a=12.0, power=2.0, tails='normal',
                    shared=True, scale=[1.0] * 8)
    clean, real = _pair(2, [effect])

    def extra(condition, sensor):
        m = clean.condition == condition
        return np.var(_residuals(real)[m, sensor]) - np.var(_residuals(clean)[m, sensor])
    # s2 faces the lamp in bulb_1ft (bright) and sees only ambient in room_dark
    assert extra('room_dark', 2) > 50
    assert extra('room_dark', 2) > 5 * abs(extra('bulb_1ft', 2))


def test_a_floor_touches_only_the_brightest_few_percent():
    effect = Limit('floor', list(range(8)), percent=3.0, fallback=70.0)
    clean, real = _pair(3, [effect])
    floor = effect.value
    at_floor = np.mean(real.readings == np.rint(floor))
    assert 0.01 < at_floor < 0.08
    assert np.all(real.readings >= np.rint(floor))
    assert np.mean(clean.readings == np.rint(floor)) < at_floor / 3


def test_a_shared_sinusoid_moves_the_named_sensors_together():
    effect = Drift('sinusoid', [1, 5], shared=True, amplitude=30.0, period_frac=0.5)
    clean, real = _pair(4, [effect])
    shift = real.readings - clean.readings
    assert np.ptp(shift[:, 1]) > 40
    assert np.corrcoef(shift[:, 1], shift[:, 5])[0, 1] > 0.9
    assert np.abs(shift[:, [0, 2, 3, 4, 6, 7]]).max() <= 1.0   # rounding at the limits only


def test_a_turn_error_scales_the_executed_turns():
    rng = np.random.default_rng(5)
    rec = robot.closed_loop(5, [TurnError('scale', [], scale=0.5, slip=0.0)], 6, rng)
    same = (rec.episode[1:] == rec.episode[:-1]) & ((rec.step[1:] % 5) != 0)
    moved = np.abs(((np.diff(rec.heading_deg) + 180) % 360) - 180)[same]
    commanded = 3.0 * rec.power[:-1][same]
    busy = commanded > 0
    assert moved[busy].sum() / commanded[busy].sum() == pytest.approx(0.5, abs=0.1)


def test_latency_delivers_readings_that_match_an_earlier_heading():
    rng = np.random.default_rng(6)
    rec = robot.closed_loop(6, [Latency('delay', list(range(8)), steps=2)], 10, rng)
    world = World(lamp_distance_mm=5.0, ambient=500.0)
    expected = world.response(rec.heading_deg[:, None] - np.asarray(SENSOR_ANGLES_DEG))
    same = (rec.episode[2:] == rec.episode[:-2])
    now = np.abs(rec.readings[2:, :6] - expected[2:, :6])[same].mean()
    earlier = np.abs(rec.readings[2:, :6] - expected[:-2, :6])[same].mean()
    assert earlier < 0.7 * now


def test_scoring_rules():
    cases = draw_cases(0, 7, 0, 0)
    single = next(c for c in cases if c['effects'][0].name == 'sensor_gain_offset')
    sensors = single['effects'][0].sensors
    diag = {'top_effect': 'sensor_gain_offset',
            'effects': [{'name': 'sensor_gain_offset', 'sensors': sensors,
                         'heldout_reduction': 0.7}]}
    s = score_case(single, diag)
    assert s['top1'] and s['location'] and s['shrink'] == 0.7
    diag['effects'][0]['sensors'] = [s for s in range(8) if s not in sensors][:1]
    assert score_case(single, diag)['location'] is False
    compound = {'kind': 'compound', 'effects': [Drift('ramp', [0], shared=False, amplitude=20),
                                                Latency('delay', list(range(8)), steps=1)]}
    by_threshold = {'top_effect': 'temporal_drift', 'effects': [
        {'name': 'temporal_drift', 'heldout_reduction': 0.5, 'p_value': 0.01},
        {'name': 'correlated_noise', 'heldout_reduction': 0.3, 'p_value': 0.2},
        {'name': 'sensor_gain_offset', 'heldout_reduction': 0.25}]}
    s = score_case(compound, by_threshold)
    assert s['predicted_from'] == 'threshold'
    assert s['predicted'] == ['temporal_drift', 'sensor_gain_offset']
    assert (s['precision'], s['recall']) == (0.5, 0.5)
    alone = dict(by_threshold, combined=None)
    s = score_case(compound, alone)
    assert s['predicted_from'] == 'top_effect'
    assert (s['predicted'], s['shrink']) == (['temporal_drift'], 0.5)
    by_set = dict(by_threshold, compound=[{'name': 'temporal_drift', 'cumulative_reduction': 0.4},
                                          {'name': 'sensor_latency',
                                           'cumulative_reduction': 0.9}])
    s = score_case(compound, by_set)
    assert (s['precision'], s['recall'], s['shrink']) == (1.0, 1.0, 0.9)


def test_a_case_gives_the_same_recording_for_its_seed(tmp_path):
    case = draw_cases(2, 7, 2, 0)[-1]           # a closed-loop compound
    assert case['protocol'] == 'closed_loop'
    a = make_recording(case, True, tmp_path / 'a')
    case = draw_cases(2, 7, 2, 0)[-1]           # fresh effects: no state carried over
    b = make_recording(case, True, tmp_path / 'b')
    assert a.with_suffix('.csv').read_text() == b.with_suffix('.csv').read_text()
