"""The closed-loop statistics (``gap.closedloop``): the noise while the robot turns, in its
three views (still steps, heading residuals where headings are recorded, change
residuals where they are not), each sensor's own delay in the heading residuals, and
the turn's scatter.

The 'robot' is the closed-loop simulator (``testing.protocols``), with hand-made
readings where a known noise is wanted.
"""
import numpy as np

from khepera_noise_ros.effects import CorrelatedNoise, SensorLatency
from khepera_noise_ros.gap import bootstrap, closedloop
from khepera_noise_ros.gap.families import FAMILIES, of_part
from khepera_noise_ros.gap.target import Target
from khepera_noise_ros.testing.protocols import CONFIG, closed_loop_protocol, recorded, tracked

NOISE = of_part('closed_loop_noise')
CHANGE = frozenset(f for f in NOISE if f.startswith('loop_change_'))
PAIR = (1, 6)                       # not adjacent
DELAYED = (0, 1, 2, 3, 4)           # a latency on five of the eight sensors


def _blocks(rec, loop_only=False):
    """The per-episode sums of ``rec`` without the converter's."""
    return closedloop.blocks(rec, rec.readings, lambda order, ep, m: {},
                             CONFIG.task.perturb_every, loop_only)


def _estimates(rec, loop_only=False) -> dict:
    """{key: full-data estimate} of the closed-loop statistics (no converter's); empty cells
    give NaN, which ``Target`` computes under the same ``errstate``."""
    b = _blocks(rec, loop_only)
    with np.errstate(invalid='ignore', divide='ignore'):
        keys, cols = closedloop.stats(b, bootstrap.resampled(b, 0, 0), lambda *a: ([], []))
    values = np.concatenate([c if c.ndim == 2 else c[:, None] for c in cols], axis=1)
    return dict(zip(keys, values[0]))


def _get(stats, family, sensors):
    return next(v for k, v in stats.items() if k.family == family and k.sensors == sensors)


def test_still_pairs_measure_noise_alone():
    """Where the robot does not turn (power 0, no knock) the first differences are noise:
    their spread is the noise's and pairs sharing noise correlate."""
    rng = np.random.default_rng(0)
    rec = tracked(closed_loop_protocol(6), seed=5)
    rec.power[:] = 0
    rec.heading_deg[:] = np.nan
    light = np.linspace(100, 500, 8)
    noise = rng.normal(0, 4.0, (len(rec), 8))
    noise[:, 6] = 0.6 * noise[:, 1] + 0.8 * noise[:, 6]
    rec.readings[:] = light + noise
    got = _estimates(rec)
    spread = [v for k, v in got.items() if k.family == 'loop_still_spread']
    assert np.allclose(spread, 4.0, rtol=0.12), spread
    corr = {k.sensors: v for k, v in got.items() if k.family == 'loop_still_correlation'}
    assert abs(corr[PAIR] - 0.6) < 0.1 and abs(corr[(0, 1)]) < 0.1


def test_heading_residuals_need_recorded_headings():
    rec = tracked(closed_loop_protocol(8), seed=5)
    families = {k.family for k in Target([rec], CONFIG, 1, replicates=20).real.keys}
    assert {'loop_residual_spread', 'loop_residual_correlation'} <= families
    assert not families & CHANGE          # tracked: the heading residuals alone
    rec.heading_deg[:] = np.nan          # a robot nobody tracked; it never stands still
    families = {k.family for k in Target([rec], CONFIG, 1, replicates=20).real.keys}
    assert not families & (NOISE - CHANGE)
    assert CHANGE <= families            # only the change residuals are left
    assert 'closed_loop_level' in families


def test_change_residuals_exist_without_headings_or_still_steps():
    rec = recorded(closed_loop_protocol(25), [SensorLatency(tuple(range(8)), 2)], seed=11)
    assert not np.isfinite(rec.heading_deg).any()
    beside = _blocks(rec)                # a stationary recording beside it ...
    assert not beside.has('chg_band_n')  # ... keeps the other statistics
    blocks = _blocks(rec, loop_only=True)
    assert blocks.part(blocks.sums, 'still_n').sum() == 0       # never a still pair
    families = {k.family for k in _estimates(rec, loop_only=True)}
    assert CHANGE and CHANGE <= families, families
    assert FAMILIES['loop_change_correlation'].part == 'closed_loop_noise'


def test_residuals_at_each_sensors_delay_are_the_noise_alone():
    """A latency of three steps on five sensors: under the undelayed fit the residuals
    of a lit one held the light of three headings back (sd 14 readings against a noise
    of 5); at their own delay they are the noise, as in the recording without the
    latency, and the pair's shared noise shows in their correlation."""
    pair = CorrelatedNoise(((1, 4),), 0.03)
    protocol = closed_loop_protocol(20)
    late = _estimates(tracked(protocol, [SensorLatency(DELAYED, 3), pair], seed=5))
    prompt = _estimates(tracked(protocol, [pair], seed=5))
    for k in range(8):
        a = _get(late, 'loop_residual_spread', (k,))
        b = _get(prompt, 'loop_residual_spread', (k,))
        assert abs(a / b - 1) < 0.3, (k, a, b)
    assert _get(late, 'loop_residual_correlation', (1, 4)) > 0.4
    assert abs(_get(late, 'loop_residual_correlation', (0, 2))) < 0.2


def test_each_sensor_takes_the_delay_its_light_shows():
    rec = tracked(closed_loop_protocol(12), [SensorLatency(DELAYED, 2)], seed=5)
    episodes, _, order, _, pair = closedloop.ordered(rec)
    e, use, lag = closedloop.residuals(rec.readings[order][:, :8].astype(float),
                                       rec.heading_deg[order], rec.condition[order], pair,
                                       episodes.size)
    # a design one step off still holds the heading in its turn terms (and a sensor on
    # a flat stretch of light fits alike at any delay: the undelayed design stays)
    late = lag[list(DELAYED)]
    assert set(late) <= {0, 2, 3} and (late > 0).sum() >= 3 and (late == 2).sum() >= 2, lag
    assert not lag[5:].any(), lag
    assert use.sum() > 0.8 * len(rec) and np.all(e[~use] == 0)


def test_the_latencys_sensor_set_leaves_out_the_sensors_that_read_at_once():
    """A latency on two of the four sensors the lamp lights here (s4-s7): the two lit
    ones that read the heading of the moment are left out of the set; s0-s3, on a flat
    light, may lag unseen and stay in.  Without headings there is no set from them."""
    rec = tracked(closed_loop_protocol(16), [SensorLatency((4, 5), 2)], seed=5)
    got = set(closedloop.delayed_sensors([rec]))
    assert {4, 5} <= got and not got & {6, 7}, got
    assert closedloop.delayed_sensors([tracked(closed_loop_protocol(16), seed=5)]) == ()
    rec.heading_deg[:] = np.nan
    assert closedloop.delayed_sensors([rec]) == ()
