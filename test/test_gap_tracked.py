"""Closed-loop recordings with headings (a tracked robot) beside a sensor latency: the
heading residuals take each sensor at its own delay (``gap.headinglag``), so the
noise's shape still shows beside a latency of up to three steps.

The 'robot' is the closed-loop simulator with hidden effects; the diagnosis sees only
the recording and the plain simulator's configuration.
"""
import numpy as np

from khepera_noise_ros.gap import diagnose, replay, statistics
from khepera_noise_ros.gap import effects as fx
from test_gap_support import CONFIG, closed_loop_protocol

OPTIONS = diagnose.Options(config=CONFIG, replicates=60)
DELAYED = (0, 1, 2, 3, 4)           # a latency on five of the eight sensors
PAIR = (1, 4)                       # not adjacent, both delayed


def tracked(effects, seed=5, episodes=20):
    rec = replay.replay(closed_loop_protocol(episodes), CONFIG, effects, seed=seed)
    rec.manifest = dict(rec.manifest, source='emulator')
    assert np.isfinite(rec.heading_deg).all()
    return rec


def _noise_stats(rec) -> dict:
    s = statistics.compute(statistics.closed_loop_blocks(rec, 5), 0)
    return {k: v for k, v in zip(s.keys, s.estimate) if k.family.startswith('loop_residual')}


def _get(stats, family, sensors):
    return next(v for k, v in stats.items() if k.family == family and k.sensors == sensors)


def test_residuals_at_each_sensors_delay_are_the_noise_alone():
    """A latency of three steps on five sensors: under the undelayed fit the residuals
    of a lit one held the light of three headings back (sd 14 readings against a noise
    of 5); at their own delay they are the noise, as in the recording without the
    latency, and the pair's shared noise shows in their correlation."""
    pair = fx.CorrelatedNoise((PAIR,), 0.03)
    late = _noise_stats(tracked([fx.SensorLatency(DELAYED, 3), pair]))
    prompt = _noise_stats(tracked([pair]))
    for k in range(8):
        a = _get(late, 'loop_residual_spread', (k,))
        b = _get(prompt, 'loop_residual_spread', (k,))
        assert abs(a / b - 1) < 0.3, (k, a, b)
    assert _get(late, 'loop_residual_correlation', PAIR) > 0.4
    assert abs(_get(late, 'loop_residual_correlation', (0, 2))) < 0.2


def test_each_sensor_takes_the_delay_its_light_shows():
    from khepera_noise_ros.gap import headinglag
    rec = tracked([fx.SensorLatency(DELAYED, 2)], episodes=12)
    episodes, ep = np.unique(rec.episode, return_inverse=True)
    order = np.lexsort((rec.step, ep))
    ep, steps = ep[order], rec.step[order]
    pair = np.r_[False, (ep[1:] == ep[:-1]) & (steps[1:] == steps[:-1] + 1)]
    e, use, lag = headinglag.residuals(rec.readings[order][:, :8].astype(float),
                                       rec.heading_deg[order], rec.condition[order], pair,
                                       episodes.size)
    # a design one step off still holds the heading in its turn terms (and a sensor on
    # a flat stretch of light fits alike at any delay: the undelayed design stays)
    late = lag[list(DELAYED)]
    assert set(late) <= {0, 2, 3} and (late > 0).sum() >= 3 and (late == 2).sum() >= 2, lag
    assert not lag[5:].any(), lag
    assert use.sum() > 0.8 * len(rec) and np.all(e[~use] == 0)


def test_a_pair_beside_a_three_step_latency_on_some_sensors_is_chosen():
    rec = tracked([fx.SensorLatency(DELAYED, 3), fx.CorrelatedNoise((PAIR,), 0.03)])
    result = diagnose.diagnose([rec], OPTIONS)
    chosen = result.to_json()['compound']['chosen']
    by = {c['name']: c for c in chosen}
    assert sorted(by) == ['correlated_noise', 'sensor_latency'], list(by)
    assert by['sensor_latency']['parameters']['steps'] == 3
    groups = by['correlated_noise']['parameters']['groups']
    assert [sorted(g) for g in groups] == [list(PAIR)], groups


def test_a_latency_alone_gains_no_sensor_effect():
    rec = tracked([fx.SensorLatency(DELAYED, 3)], seed=7)
    result = diagnose.diagnose([rec], OPTIONS)
    out = result.to_json()
    names = [c['name'] for c in out['compound']['chosen']] if out['compound'] else \
        [out['top_effect']]
    assert names == ['sensor_latency'], names


def test_the_latencys_sensor_set_leaves_out_the_sensors_that_read_at_once():
    """A latency on two of the four sensors the lamp lights here (s4-s7): the two lit
    ones that read the heading of the moment are left out of the set; s0-s3, on a flat
    light, may lag unseen and stay in.  Without headings there is no set from them."""
    from khepera_noise_ros.gap import fitlatency
    rec = tracked([fx.SensorLatency((4, 5), 2)], episodes=16)
    got = set(fitlatency.delayed_sensors([rec]))
    assert {4, 5} <= got and not got & {6, 7}, got
    assert fitlatency.delayed_sensors([tracked([], episodes=16)]) == ()
    rec.heading_deg[:] = np.nan
    assert fitlatency.delayed_sensors([rec]) == ()
