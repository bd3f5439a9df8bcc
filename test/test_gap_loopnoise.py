"""Noise in closed-loop-only recordings beside a loop effect (``gap.loopchange``).

A robot that logs only while it runs its task, without headings: the project's
controller never stands still, so neither closed-loop noise view of ``gap.closednoise``
exists, and a sensor effect beside a latency was never chosen.  The change residuals
carry the noise: shared pairs, extra spread."""
import numpy as np

from khepera_noise_ros.gap import closedloop, closednoise, compound, diagnose, loopchange
from khepera_noise_ros.gap import effects as fx
from khepera_noise_ros.gap.target import Target
from test_gap_support import CONFIG, closed_loop_protocol, recorded

EPISODES = 25
PAIR = (0, 3)                        # not adjacent; both read dark much of the time
LATENCY = fx.SensorLatency(tuple(range(8)), 2)
SHARED = fx.CorrelatedNoise((PAIR,), 0.02)


def loop_only(effects, seed):
    return recorded(closed_loop_protocol(EPISODES), effects, seed=seed)


def _rows(c, family):
    return [(k, z) for k, z in zip(c.keys, c.z) if k.family == family]


def test_change_residuals_exist_without_headings_or_still_steps():
    rec = loop_only([LATENCY], seed=11)
    assert not np.isfinite(rec.heading_deg).any()
    beside = closedloop.closed_loop_blocks(rec, 5)     # a stationary recording beside it
    assert 'chg_band_n' not in beside.layout               # ... keeps the old statistics
    blocks = closedloop.closed_loop_blocks(rec, 5, loop_only=True)
    assert blocks.part(blocks.sums, 'still_n').sum() == 0       # never a still pair
    stats = closedloop.closed_loop_stats(blocks, blocks.sums[None].sum(axis=1)[:, None])
    families = {k.family for k in stats.keys}
    assert loopchange.FAMILIES <= families, families
    assert loopchange.FAMILIES <= closednoise.FAMILIES
    assert compound._protocol('loop_change_correlation') == 'closed_loop_noise'


def test_a_shared_pair_shows_beside_the_latency_and_a_clean_loop_does_not():
    given = Target([loop_only([LATENCY, SHARED], seed=12)], CONFIG, 3, replicates=60)
    c = given.compare([LATENCY], replicates=60)
    z = dict(_rows(c, 'loop_change_correlation'))
    pair = [v for k, v in z.items() if k.sensors == PAIR]
    assert pair and pair[0] > 4, z
    evidence = closednoise.evidence(c, range(8))
    assert evidence[PAIR] == evidence.max(), evidence
    clean = Target([loop_only([LATENCY], seed=13)], CONFIG, 3, replicates=60)
    c0 = clean.compare([LATENCY], replicates=60)
    zs = np.array([v for f in loopchange.FAMILIES for _, v in _rows(c0, f)])
    assert zs.size > 30 and np.nanmax(np.abs(zs)) < 4.5, zs


def _chosen(effects, seed):
    out = diagnose.diagnose([loop_only(effects, seed)], diagnose.Options(
        config=CONFIG, replicates=60, remainder=False)).to_json()
    return out['compound']['chosen']


def test_latency_and_shared_pair_are_both_chosen_and_a_clean_latency_alone():
    chosen = _chosen([LATENCY, SHARED], seed=14)
    names = [s['name'] for s in chosen]
    assert names[0] == 'sensor_latency' and 'correlated_noise' in names, chosen
    groups = chosen[names.index('correlated_noise')]['parameters']['groups']
    assert [sorted(g) for g in groups] == [list(PAIR)], groups
    clean = _chosen([LATENCY], seed=15)         # control: no false sensor effect
    assert [s['name'] for s in clean] == ['sensor_latency'], clean
