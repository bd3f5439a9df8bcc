"""The generator: foreign robots drawn from a seed, in the forms of ``light``,
``actuator`` and ``sensing`` and within the ranges below.

The ranges were written down before any robot was drawn or measured, from what a
Khepera's parts plausibly do, and are never moved after seeing a result.  Robot-level
values are uniform in their range; per-sensor values scatter around them.
"""
from __future__ import annotations

import numpy as np

from .params import FORMAT, check

NOMINAL_AXES_DEG = (90.0, 45.0, 10.0, -10.0, -45.0, -90.0, -170.0, 170.0)   # s0 .. s7
RANGES = {
    # light: the ring's mounting, each cell's lobe and photocell
    'ring_offset_deg': (-8.0, 8.0),        # the whole ring turned on the body
    'axis_sd_deg': 4.0,                    # each sensor's own axis error (normal sd)
    'width_deg': (22.0, 42.0),             # lobe half-width at half light
    'width_log_sd': 0.25,                  # each side of each lobe: width x exp(N(0, sd))
    'shape': (1.2, 3.5),                   # 1 peaked, 2 Gaussian, > 2 flat-topped
    'shape_log_sd': 0.15,
    'leak': (0.0, 0.02),
    'lamp_power': (6.0, 16.0),             # lamp light at the task's distance, in half-scales
    'lamp_near_mm': (50.0, 150.0),
    'room_flux': (1.2, 3.0),
    'sensitivity_log_sd': 0.2,
    'dark': (490.0, 520.0),
    'floor': (30.0, 80.0), 'floor_sd': 10.0,
    'hill': (0.9, 1.8), 'hill_log_sd': 0.1,
    # actuator
    'gain': (0.7, 1.3), 'asymmetry': (-0.15, 0.15), 'exponent': (0.75, 1.3),
    'dead_band_deg': (1.0, 5.0), 'backlash_deg': (0.0, 2.0),
    'scatter': (0.03, 0.12), 'jitter_deg': (0.1, 0.8),
    # sensor dynamics: kind with its probability, then per-sample rates and delay
    'kind': {'lag': 0.35, 'delay': 0.2, 'lag_delay': 0.45},
    'brighten': (0.35, 0.9), 'darken': (0.25, 0.8), 'delay': (0.3, 1.6),
    # noise
    'flicker': (0.005, 0.03), 'flicker_samples': (5.0, 80.0), 'shot': (0.05, 0.35),
    'step': (1, 1, 2, 4),
}


def draw_robot(seed: int, index: int) -> dict:
    """Robot ``index`` of generator ``seed``: checked parameters (``params.check``)."""
    rng = np.random.default_rng([int(seed), int(index)])
    r = RANGES

    def uniform(key):
        return float(rng.uniform(*r[key]))

    def scatter(base, key, low, high):
        return np.clip(base * np.exp(rng.normal(0.0, r[key], 8)), low, high)

    axes = np.asarray(NOMINAL_AXES_DEG) + uniform('ring_offset_deg') + \
        np.clip(rng.normal(0.0, r['axis_sd_deg'], 8), -10.0, 10.0)
    width = uniform('width_deg')
    dark = rng.uniform(*r['dark'], 8)
    light = {
        'lamp_power': uniform('lamp_power'), 'lamp_near_mm': uniform('lamp_near_mm'),
        'room_flux': uniform('room_flux'),
        'axis_deg': (axes + 180.0) % 360.0 - 180.0,
        'width_ccw_deg': scatter(width, 'width_log_sd', 12.0, 70.0),
        'width_cw_deg': scatter(width, 'width_log_sd', 12.0, 70.0),
        'shape': scatter(uniform('shape'), 'shape_log_sd', 1.0, 4.5),
        'leak': rng.uniform(*r['leak'], 8),
        'sensitivity': scatter(1.0, 'sensitivity_log_sd', 0.4, 2.5),
        'dark': dark,
        'floor': np.clip(uniform('floor') + rng.normal(0.0, r['floor_sd'], 8), 5.0, 150.0),
        'hill': scatter(uniform('hill'), 'hill_log_sd', 0.5, 3.0),
    }
    act = {k: uniform(k) for k in ('gain', 'asymmetry', 'exponent', 'dead_band_deg',
                                   'backlash_deg', 'scatter', 'jitter_deg')}
    kinds = list(r['kind'])
    kind = kinds[rng.choice(len(kinds), p=list(r['kind'].values()))]
    lagging, late = kind != 'delay', kind != 'lag'
    dynamics = {'kind': kind,
                'brighten': uniform('brighten') if lagging else 1.0,
                'darken': uniform('darken') if lagging else 1.0,
                'delay': uniform('delay') if late else 0.0}
    noise = {'flicker': uniform('flicker'), 'flicker_samples': uniform('flicker_samples'),
             'shot': uniform('shot'), 'step': int(rng.choice(r['step']))}
    data = {'format': FORMAT, 'name': f'foreign_{index:02d}',
            'drawn': {'generator': 'benchmark/foreign/draw.py', 'seed': int(seed),
                      'index': int(index)},
            'unit_seed': int(rng.integers(2 ** 31)),
            'light': light, 'actuator': act, 'dynamics': dynamics, 'noise': noise}
    return check(data, data['name'])
