"""Small generated recordings for the gap tests, and tests of the statistics themselves.

Recordings are made by the simulator (``gap.replay``) with or without an effect of
``gap.effects``: the diagnosis sees only the recording, and the effect's settings
stay here.  The protocol is small so that every gap test runs in about a second.
"""
import numpy as np
import pytest

from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.gap import replay, statistics, where
from khepera_noise_ros.simconfig import SimConfig
from khepera_noise_ros.recording import FORMAT, Recording

CONDITIONS = {'task': {'lamp_distance_mm': 5.0, 'ambient': 500.0},
              'bulb_2ft': {'lamp_distance_mm': 130.0, 'ambient': 500.0},
              'room_fluorescent': {'lamp_distance_mm': 1e4, 'ambient': 250.0}}
SWEEP = (10, -90, 45, -170, -10, 90, -45, 170)
CONFIG = SimConfig(noise=NoiseModel.independent_only(0.02))
GENOME = [0.9, -0.6, 0.5, -0.4, 0.7, 0.3, -0.8, 0.9, -0.5, 0.6, -0.9, -0.2, 2.5, -1.5, -2.5,
          1.5, 0.1, -0.1, 0.2, 0.3]


def manifest(protocol: str, conditions=CONDITIONS, **extra) -> dict:
    return {'format': FORMAT, 'source': 'simulator', 'sample_period_s': 1.0,
            'protocol': protocol, 'conditions': dict(conditions), **extra}


def stationary_protocol(samples: int = 30, repeats: int = 2, channels: int = 8,
                        conditions=CONDITIONS) -> Recording:
    """Each episode sweeps the lamp over every sensor's axis in one condition."""
    rows, episode = [], 0
    for _ in range(repeats):
        for label, world in conditions.items():
            headings = SWEEP if world['lamp_distance_mm'] < 1e3 else (0,)
            t = 0
            for heading in headings:
                for _ in range(samples * (1 if len(headings) > 1 else 4)):
                    rows.append((episode, t, heading, label))
                    t += 1
            episode += 1
    e, s, h, c = zip(*rows)
    n = len(rows)
    return Recording(np.array(e), np.array(s), np.array(h, float), np.array(c),
                     np.zeros((n, channels)), np.full(n, np.nan), np.full(n, np.nan),
                     manifest('stationary', conditions))


def closed_loop_protocol(episodes: int = 24, steps: int = 60) -> Recording:
    n = episodes * steps
    return Recording(np.repeat(np.arange(episodes), steps), np.tile(np.arange(steps), episodes),
                     np.full(n, np.nan), np.full(n, 'task'), np.zeros((n, 8)), np.ones(n),
                     np.ones(n), manifest('closed_loop', {'task': CONDITIONS['task']},
                                          genome=GENOME))


def recorded(protocol: Recording, effects=(), config=CONFIG, seed=99) -> Recording:
    """The protocol 'recorded' from a robot that has ``effects``; headings unknown in
    closed loop, as on a real robot."""
    rec = replay.replay(protocol, config, effects, seed=seed)
    rec.manifest = dict(protocol.manifest, source='emulator')
    if replay.kind(rec) == 'closed_loop':
        rec.heading_deg[:] = np.nan
    return rec


def _stats(rec: Recording, seed: int) -> statistics.Stats:
    blocks = statistics.stationary_blocks(rec, range(8), statistics.block_length(rec, range(8)))
    return statistics.compute(blocks, replicates=100, seed=seed)


def test_the_same_simulator_twice_differs_by_chance_only():
    protocol = stationary_protocol()
    c = where.compare(_stats(recorded(protocol, seed=1), 1), _stats(recorded(protocol, seed=2), 2))
    assert not c.significant().any()
    assert 0.7 < np.std(c.z) < 1.4         # standardised differences are about N(0, 1)


def test_a_real_difference_is_significant_and_ranked_first():
    protocol = stationary_protocol()
    noisier = SimConfig(noise=NoiseModel.independent_only(0.04))
    c = where.compare(_stats(recorded(protocol, config=noisier, seed=1), 1),
                      _stats(recorded(protocol, seed=2), 2))
    top = where.entries(c, limit=5)
    assert c.significant().sum() > 20
    assert top[0]['statistic'] == 'spread' and top[0]['real'] > top[0]['sim']


def test_autocorrelation_and_block_length_follow_the_data():
    rng = np.random.default_rng(0)
    protocol = stationary_protocol(samples=60, repeats=1)
    rec = recorded(protocol)
    x = np.zeros(len(rec))
    for t in range(1, len(rec)):                 # AR(1) with coefficient 0.8 on sensor 0
        x[t] = 0.8 * x[t - 1] + rng.normal(0, 5)
    rec.readings[:, 0] = 300 + np.round(x)
    s = _stats(rec, 0)
    acf = [v for k, v in zip(s.keys, s.estimate) if k.family == 'autocorrelation'
           and k.sensors == (0,) and k.part == 'lag 1']
    assert np.mean(acf) == pytest.approx(0.8, abs=0.1)
    assert statistics.block_length(rec, [0]) > statistics.block_length(recorded(protocol), [0])


def test_holm_adjusts_and_keeps_order():
    p = np.array([0.01, 0.04, 0.03, 0.5])
    adjusted = where.holm(p)
    assert adjusted.tolist() == pytest.approx([0.04, 0.09, 0.09, 0.5])


def sums_both_ways(rec: Recording, block: int, flag: str) -> tuple:
    """(block sums by the shortcut the layout's ``flag`` allows, by the general path) of
    ``rec``: the flag must be set, and is cleared only while the general path runs."""
    shortcut = statistics.stationary_blocks(rec, rec.channels_used, block)
    lay = statistics._layout(rec, block)
    assert lay[flag]
    lay[flag] = False
    try:
        general = statistics.stationary_blocks(rec, rec.channels_used, block)
    finally:
        lay[flag] = True
    return shortcut, general
