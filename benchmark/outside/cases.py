"""Drawing cases: which effects, in which shapes, where and how strong.

Single-effect cases cycle through the vocabulary so every name gets its share;
compound cases take 2-4 different names at once, alternately from the sensor
effects only (a stationary recording) and with latency or turn error among them
(closed loop).  A case whose effects need
turn commands (latency, turn error) is recorded in closed loop, any other as
a stationary recording.  Everything comes from one ``numpy`` generator, so a
seed gives the same cases.
"""
from __future__ import annotations

import numpy as np

from .shapes import CLOSED_LOOP_ONLY, SENSORS, Drift, GainOffset, Groups, Latency, Limit, \
    Spread, TurnError

NAMES = ('intensity_dependent_noise', 'correlated_noise', 'temporal_drift',
         'saturation_quantization', 'sensor_gain_offset', 'sensor_latency',
         'actuator_turn_error')


def _subset(rng, low: int, high: int) -> list[int]:
    return sorted(rng.choice(SENSORS, int(rng.integers(low, high + 1)), replace=False).tolist())


def spread(rng, closed_loop=False):
    law = str(rng.choice(['bright_power', 'dark_power', 'affine', 'log', 'piecewise']))
    shared = bool(rng.random() < 0.5)
    sensors = list(range(SENSORS)) if rng.random() < 0.5 else _subset(rng, 2, 5)
    a = float(rng.uniform(8.0, 16.0))
    p = {'a': a, 'tails': str(rng.choice(['normal', 'laplace'])), 'shared': shared}
    if law in ('bright_power', 'dark_power'):
        p['power'] = float(rng.choice([0.5, 1.5, 2.0, 3.0]))
    elif law == 'affine':
        p['c'] = float(rng.uniform(2.0, 5.0))
    elif law == 'log':
        p['k'] = float(rng.uniform(5.0, 50.0))
    else:
        p['knee'] = float(rng.uniform(0.3, 0.6))
        p['low'] = float(rng.uniform(0.0, 0.2))
    p['scale'] = [1.0] * len(sensors) if shared \
        else rng.uniform(0.6, 1.4, len(sensors)).round(2).tolist()
    return Spread(law, sensors, **p)


def groups(rng, closed_loop=False):
    shape = str(rng.choice(['nonadjacent_pairs', 'triple', 'one_big', 'mixed']))
    order = rng.permutation(SENSORS).tolist()
    if shape == 'nonadjacent_pairs':
        pairs, free = [], list(range(SENSORS))
        for _ in range(int(rng.integers(1, 4))):
            a = int(rng.choice(free))
            far = [b for b in free if b != a and abs(a - b) not in (1, SENSORS - 1)]
            if not far:
                break
            b = int(rng.choice(far))
            pairs.append(sorted([a, b]))
            free = [s for s in free if s not in (a, b)]
        found = pairs
    elif shape == 'triple':
        found = [sorted(order[:3])]
    elif shape == 'one_big':
        found = [sorted(order[:int(rng.integers(5, 8))])]
    else:
        sizes = [2, 3] if rng.random() < 0.5 else [2, 2, 3]
        found, at = [], 0
        for size in sizes:
            found.append(sorted(order[at:at + size]))
            at += size
    sd = rng.uniform(8.0, 18.0, len(found)).round(2).tolist()
    weights = [rng.uniform(0.7, 1.3, len(g)).round(2).tolist() for g in found]
    sensors = sorted({s for g in found for s in g})
    return Groups(shape, sensors, groups=found, sd=sd, weights=weights)


def drift(rng, closed_loop=False):
    shape = str(rng.choice(['random_walk', 'sinusoid', 'steps', 'ramp']))
    shared = bool(rng.random() < 0.5)
    sensors = list(range(SENSORS)) if shared and rng.random() < 0.6 else _subset(rng, 1, 4)
    p = {'shared': shared, 'amplitude': float(rng.uniform(15.0, 40.0))}
    if shape == 'sinusoid':
        p['period_frac'] = float(rng.uniform(0.15, 0.6))
    elif shape == 'steps':
        p['jumps'] = int(rng.integers(1, 4))
    return Drift(shape, sensors, **p)


def limit(rng, closed_loop=False):
    shapes = ['lattice', 'dropout'] if closed_loop else ['floor', 'ceiling', 'lattice', 'dropout']
    shape = str(rng.choice(shapes))
    if shape in ('floor', 'ceiling'):
        sensors = list(range(SENSORS)) if rng.random() < 0.5 else _subset(rng, 3, 6)
        return Limit(shape, sensors, percent=float(rng.uniform(2.0, 5.0)),
                     fallback=70.0 if shape == 'floor' else 505.0)
    if shape == 'lattice':
        return Limit(shape, list(range(SENSORS)), step=float(rng.choice([8, 12, 16, 24])))
    return Limit(shape, _subset(rng, 1, 3), rate=float(rng.uniform(0.005, 0.02)),
                 stuck_at=float(rng.choice([0.0, 525.0])))


def gain_offset(rng, closed_loop=False):
    sensors = _subset(rng, 2, 4)
    shape = str(rng.choice(['gain', 'offset', 'both']))
    n = len(sensors)
    gain = np.ones(n)
    offset = np.zeros(n)
    if shape in ('gain', 'both'):
        gain = rng.choice([-1, 1], n) * rng.uniform(0.12, 0.3, n) + 1.0
    if shape in ('offset', 'both'):
        offset = rng.choice([-1, 1], n) * rng.uniform(10.0, 30.0, n)
    return GainOffset(shape, sensors, gain=gain.round(3).tolist(), offset=offset.round(1).tolist())


def latency(rng, closed_loop=True):
    return Latency('delay', list(range(SENSORS)), steps=int(rng.integers(1, 4)))


def turn_error(rng, closed_loop=True):
    shape = str(rng.choice(['scale', 'slip', 'both']))
    scale = float(rng.choice([rng.uniform(0.45, 0.75), rng.uniform(1.3, 1.7)])) \
        if shape != 'slip' else 1.0
    slip = float(rng.uniform(1.0, 2.5)) if shape != 'scale' else 0.0
    return TurnError(shape, [], scale=scale, slip=slip)


DRAW = {'intensity_dependent_noise': spread, 'correlated_noise': groups,
        'temporal_drift': drift, 'saturation_quantization': limit,
        'sensor_gain_offset': gain_offset, 'sensor_latency': latency,
        'actuator_turn_error': turn_error}


def draw_cases(seed: int, singles: int, compounds: int, controls: int) -> list[dict]:
    """Case specs: {'id', 'kind', 'protocol', 'seed', 'effects': [Effect, ...]}."""
    rng = np.random.default_rng([seed, 13])
    cases = []
    for i in range(singles):
        name = NAMES[i % len(NAMES)]
        cases.append(_case(len(cases), 'single', [name], rng))
    sensing = [n for n in NAMES if n not in CLOSED_LOOP_ONLY]
    for j in range(compounds):
        # half stationary (sensor effects only), half closed loop (with latency or turn error)
        k = int(rng.integers(2, 5))
        if j % 2 == 0:
            names = rng.choice(sensing, k, replace=False).tolist()
        else:
            first = [str(rng.choice(CLOSED_LOOP_ONLY))]
            rest = [n for n in NAMES if n not in first]
            names = first + rng.choice(rest, k - 1, replace=False).tolist()
        cases.append(_case(len(cases), 'compound', names, rng))
    for _ in range(controls):
        cases.append(_case(len(cases), 'control', [], rng))
    return cases


def _case(index: int, kind: str, names: list[str], rng) -> dict:
    closed = any(n in CLOSED_LOOP_ONLY for n in names)
    effects = [DRAW[n](rng, closed_loop=closed) for n in names]
    return {'id': index, 'kind': kind, 'protocol': 'closed_loop' if closed else 'stationary',
            'seed': int(rng.integers(0, 2**31 - 1)), 'effects': effects}
