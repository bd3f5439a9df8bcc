"""Value statistics of closed-loop-only recordings (``gap.loopvalues``): a value lattice
shows in the closed loop's readings whatever the heading, is judged there beside a loop
effect, and a clean recording, or readings held at one value, shows none."""
import numpy as np

from khepera_noise_ros.gap import compound, diagnose, fit, loopvalues, statistics
from khepera_noise_ros.gap import effects as fx
from khepera_noise_ros.gap.target import Target
from test_gap_support import CONFIG, closed_loop_protocol, recorded, stationary_protocol

LATTICE = fx.SaturationQuantization(tuple(range(8)), step=4.0)


def _shares(stats, q):
    index = stats.index()
    return {k.sensors[0]: stats.estimate[index[k]] for k in stats.keys
            if k.family == 'loop_granularity' and k.part == f'step {q}'}


def _closed(effects, seed, episodes=24):
    return recorded(closed_loop_protocol(episodes), effects, seed=seed)


def test_a_lattice_shows_in_closed_loop_readings():
    """Readings on multiples of 4: every value a sensor takes inside its range lies on
    one residue modulo 2 and 4; a clean recording's values spread over the residues."""
    for effects, expect in (([LATTICE], 1.0), ([], None)):
        rec = _closed(effects, seed=11)
        stats = statistics.compute(statistics.closed_loop_blocks(rec, 5, loop_only=True), 50)
        for q in (2, 4):
            share = _shares(stats, q)
            assert len(share) == 8, share
            for v in share.values():
                if expect is None:
                    assert v < 1.0 / q + 0.2, (q, share)
                else:
                    assert v == expect, (q, share)


def test_value_statistics_only_without_a_stationary_part():
    """Beside a stationary recording (which has its own granularity) they are not added."""
    closed = _closed([], seed=12, episodes=8)
    stationary = recorded(stationary_protocol(), [], seed=12)
    alone = Target([closed], CONFIG, 1, replicates=20)
    both = Target([stationary, closed], CONFIG, 1, replicates=20)
    assert any(k.family == 'loop_granularity' for k in alone.real.keys)
    assert not any(k.family == 'loop_granularity' for k in both.real.keys)
    plain = statistics.compute(statistics.closed_loop_blocks(closed, 5), 0)
    assert not any(k.family in loopvalues.FAMILIES for k in plain.keys)


def test_a_value_held_is_not_a_lattice():
    """A sensor parked at one reading (the light model's brightest, a robot at the lamp)
    for most samples: each value counts once, so the residue share stays near 1/q."""
    rng = np.random.default_rng(3)
    r = np.where(rng.random((3000, 8)) < 0.8, 50.0, rng.integers(40, 400, (3000, 8)))
    weight, on = loopvalues.on_lattice(r)
    share = (weight[..., None] * on).sum(axis=0) / weight.sum(axis=0)[:, None]
    q2 = loopvalues.MODULI.index(2)
    assert np.all(share[:, q2] < 0.6), share[:, q2]
    # the same readings every one on a multiple of 2 are a lattice
    weight, on = loopvalues.on_lattice(2 * np.round(r / 2))
    share = (weight[..., None] * on).sum(axis=0) / weight.sum(axis=0)[:, None]
    assert np.all(share[:, q2] == 1.0), share[:, q2]


def test_a_clean_closed_loop_recording_shows_no_lattice():
    """Real against simulated, no effect: no granularity statistic is off."""
    rec = _closed([], seed=13)
    target = Target([rec], CONFIG, 1, replicates=60)
    c = target.compare()
    z = [abs(z) for k, z in zip(c.keys, c.z) if k.family == 'loop_granularity']
    assert len(z) == 8 * len(loopvalues.MODULI)
    assert max(z) < 4.0, max(z)
    assert fit.saturation(target, c).effect is None


def test_the_saturation_fitter_reads_the_closed_loop_lattice():
    rec = _closed([LATTICE], seed=14)
    target = Target([rec], CONFIG, 1, replicates=60)
    c = target.compare()
    flagged = {k.sensors[0] for k, z in zip(c.keys, c.z)
               if k.family == 'loop_granularity' and z > fit.Z_DETECT}
    assert flagged == set(range(8)), flagged
    cand = fit.saturation(target, c)
    assert cand.effect is not None and cand.effect.step == 4.0, cand


def test_a_lattice_beside_a_latency_is_chosen_in_closed_loop_only():
    """The loop effect takes nearly all of the closed loop's discrepancy; the lattice is
    judged on its own part (``loop_values``) and chosen too."""
    hidden = [fx.SensorLatency(tuple(range(8)), 2), LATTICE]
    rec = _closed(hidden, seed=15)
    out = diagnose.diagnose([rec], diagnose.Options(config=CONFIG, replicates=60,
                                                    remainder=False)).to_json()
    chosen = {s['name']: s for s in out['compound']['chosen']}
    assert set(chosen) == {'sensor_latency', 'saturation_quantization'}, list(chosen)
    assert chosen['saturation_quantization']['parameters']['step'] == 4.0
    assert compound._protocol('loop_granularity') == 'loop_values'
