"""Small recordings made by the simulator with hidden effects, for the diagnosis's tests.

A protocol is a recording's index columns (episodes, steps, headings, conditions) with
empty readings; ``recorded`` fills them as a robot that has the given effects would (the
simulator's replay with the effects added).  The diagnosis sees only the recording and
the plain simulator's configuration; the effects' settings stay in the test.  The
protocols are small so that a diagnosis of one takes about a second.
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from ..core.noise import NoiseModel
from ..effects import Effect
from ..gap.protocol import kind
from ..gap.replay import Replayer
from ..simconfig import SimConfig
from ..recording import FORMAT, Recording

CONDITIONS = {'task': {'lamp_distance_mm': 5.0, 'ambient': 500.0},
              'bulb_2ft': {'lamp_distance_mm': 130.0, 'ambient': 500.0},
              'room_fluorescent': {'lamp_distance_mm': 1e4, 'ambient': 250.0}}
SWEEP = (10, -90, 45, -170, -10, 90, -45, 170)
CONFIG = SimConfig(noise=NoiseModel.independent_only(0.02))
GENOME = [0.9, -0.6, 0.5, -0.4, 0.7, 0.3, -0.8, 0.9, -0.5, 0.6, -0.9, -0.2, 2.5, -1.5, -2.5,
          1.5, 0.1, -0.1, 0.2, 0.3]


def manifest(protocol: str, conditions: Mapping[str, Any] = CONDITIONS,
             **extra: Any) -> dict[str, Any]:
    return {'format': FORMAT, 'source': 'simulator', 'sample_period_s': 1.0,
            'protocol': protocol, 'conditions': dict(conditions), **extra}


def stationary_protocol(samples: int = 30, repeats: int = 2, channels: int = 8,
                        conditions: Mapping[str, Any] = CONDITIONS) -> Recording:
    """Each episode sweeps the lamp over every sensor's axis in one condition (one heading,
    four times as long, where the lamp is too far to tell headings apart)."""
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
    """``episodes`` of the task in its own condition, run by the controller ``GENOME``."""
    n = episodes * steps
    return Recording(np.repeat(np.arange(episodes), steps), np.tile(np.arange(steps), episodes),
                     np.full(n, np.nan), np.full(n, 'task'), np.zeros((n, 8)), np.ones(n),
                     np.ones(n), manifest('closed_loop', {'task': CONDITIONS['task']},
                                          genome=GENOME))


def sweep(step: float = 20.0, samples: int = 20, within: bool = False) -> Recording:
    """Placements every ``step`` degrees where the lamp is on (one heading where it is
    off): one episode each as the record command does, or (``within``) one episode per
    condition turned from heading to heading without a pause."""
    rows, episode = [], 0
    for label, world in CONDITIONS.items():
        heads = np.arange(-180.0, 180.0, step) if world['lamp_distance_mm'] < 1e3 else [0.0]
        t = 0
        for h in heads:
            rows += [(episode, t + i, h, label) for i in range(samples)]
            t, episode = (t + samples, episode) if within else (0, episode + 1)
        episode += within
    e, s, h, c = (np.array(v) for v in zip(*rows))
    n = len(rows)
    return Recording(e, s, h.astype(float), c, np.zeros((n, 8)), np.full(n, np.nan),
                     np.full(n, np.nan), manifest('stationary', CONDITIONS))


def turn_calibration(repeats: int = 3, rest: int = 10) -> Recording:
    """Per power and repeat a placement, then 4 turns of that power right and left in
    turn, each after ``rest`` readings at rest (the record command's protocol)."""
    rows, episode = [], 0
    for _ in range(repeats):
        for power in range(1, 10):
            for t in range(rest * 5):
                k = (t + 1) // rest - 1
                turn = (t + 1) % rest == 0 and k < 4
                rows.append((episode, t, -power * 1.5 if t == 0 else np.nan, 'turns_task',
                             (1 if k % 2 == 0 else -1) if turn else 1, power if turn else 0))
            episode += 1
    e, s, h, c, d, p = (np.array(v) for v in zip(*rows))
    n = len(rows)
    return Recording(e, s, h.astype(float), c, np.zeros((n, 8)), d.astype(float),
                     p.astype(float), manifest(
                         'closed_loop', {'turns_task': CONDITIONS['task']},
                         calibration='turns', task={'steps': rest * 5, 'perturb_every': 5,
                                                    'perturbation_deg': 0.0}))


def replayed(protocol: Recording, effects: Sequence[Effect] = (), config: SimConfig = CONFIG,
             seed: int = 99, copies: int = 1) -> Recording:
    """The simulator's replay of ``protocol`` with ``effects`` added (headings kept)."""
    return Replayer(protocol, config).replay(tuple(effects), seed, copies)


def recorded(protocol: Recording, effects: Sequence[Effect] = (), config: SimConfig = CONFIG,
             seed: int = 99) -> Recording:
    """The protocol 'recorded' from a robot that has ``effects``; headings unknown in
    closed loop, as on a real robot."""
    rec = replayed(protocol, effects, config, seed)
    rec.manifest = dict(protocol.manifest, source='emulator')
    if kind(rec) == 'closed_loop':
        rec.heading_deg = np.full(len(rec), np.nan)
    return rec


def tracked(protocol: Recording, effects: Sequence[Effect] = (), config: SimConfig = CONFIG,
            seed: int = 99) -> Recording:
    """A closed-loop recording that keeps its headings (a tracked robot)."""
    rec = replayed(protocol, effects, config, seed)
    rec.manifest = dict(rec.manifest, source='emulator')
    return rec


def dropped(rec: Recording, sensors: Sequence[int], rate: float, value: float,
            seed: int = 11) -> Recording:
    """``rec`` with each reading of ``sensors`` replaced by ``value`` at ``rate`` (dropouts
    put in by hand)."""
    readings = rec.readings.copy()
    rng = np.random.default_rng(seed)
    for s in sensors:
        readings[rng.random(len(rec)) < rate, s] = value
    return Recording(rec.episode.copy(), rec.step.copy(), rec.heading_deg.copy(),
                     rec.condition.copy(), readings, rec.direction.copy(), rec.power.copy(),
                     dict(rec.manifest))
