"""Dropouts alone and beside other effects: detection and the compound's choice (prints).

    python benchmark/dropout_cases.py [--only NAME] [--replicates 40] [--samples 60]
                                      [--episodes 24]

Each case is a recording made by the simulator (``test_gap_support``: stationary,
``--samples`` per heading and condition, or ``--episodes`` of 60 steps) with an
effect of the vocabulary or none, in which readings are then replaced by hand: each
reading of the chosen sensors, with probability ``rate``, reads ``value`` (a dropout).
The diagnosis gets the edited recording and the plain simulator.  Per case it prints
whether ``saturation_quantization`` was fitted with a dropout on the right sensors,
the top effect, and the compound's chosen set.  Controls (no dropouts) must not get one.
"""
from __future__ import annotations

import argparse
import copy
import os
import sys
import time
from pathlib import Path

for var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(var, '1')
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))

import numpy as np  # noqa: E402
from test_gap_support import CONFIG, closed_loop_protocol, recorded, \
    stationary_protocol  # noqa: E402

from khepera_noise_ros.gap import diagnose  # noqa: E402
from khepera_noise_ros.gap import effects as fx  # noqa: E402

ALL = tuple(range(8))
GAIN = fx.SensorGainOffset((2, 5), (1.12, 0.9), (4.0, -6.0))
SPREAD = fx.IntensityDependentNoise(ALL, 0.04, 2.0)
GROUPS = fx.CorrelatedNoise(((1, 2, 3),), 0.02)
DRIFT = fx.TemporalDrift(ALL, 0.012, 30.0, True)
LATENCY = fx.SensorLatency((0, 1, 2, 3), 1)
TURN = fx.ActuatorTurnError(0.7, 0.1)
CEILING = fx.SaturationQuantization(ALL, 0.0, 500.0)


def drop(rec, sensors, rate: float, value: float, seed: int):
    """``rec`` with each reading of ``sensors`` replaced by ``value`` at ``rate``."""
    out = copy.deepcopy(rec)
    rng = np.random.default_rng(seed)
    for s in sensors:
        hit = rng.random(len(out)) < rate
        out.readings[hit, s] = value
    return out


SIZE = {'samples': 60, 'episodes': 24}


def recording(kind: str, effects, seed: int):
    if kind == 'closed':
        return recorded(closed_loop_protocol(SIZE['episodes']), effects, seed=seed)
    return recorded(stationary_protocol(samples=SIZE['samples']), effects, seed=seed)


# name: (kinds, other effects, dropout sensors, rate, value)
CASES = {
    'alone one 2% to 0': (('stat',), (), (3,), 0.02, 0.0),
    'alone one 0.5% to 0': (('stat',), (), (3,), 0.005, 0.0),
    'alone three 1% to 525': (('stat',), (), (1, 4, 6), 0.01, 525.0),
    'alone all 0.2% to 0': (('stat',), (), ALL, 0.002, 0.0),
    'alone all 5% to 0': (('stat',), (), ALL, 0.05, 0.0),
    'alone all 1% to 525': (('stat',), (), ALL, 0.01, 525.0),
    'gain + three 1% to 0': (('stat',), (GAIN,), (1, 4, 6), 0.01, 0.0),
    'spread law + all 1% to 0': (('stat',), (SPREAD,), ALL, 0.01, 0.0),
    'groups + three 1% to 525': (('stat',), (GROUPS,), (1, 4, 6), 0.01, 525.0),
    'drift + all 0.5% to 0': (('stat',), (DRIFT,), ALL, 0.005, 0.0),
    'latency + three 1% to 0': (('stat',), (LATENCY,), (1, 4, 6), 0.01, 0.0),
    'closed alone all 1% to 0': (('closed',), (), ALL, 0.01, 0.0),
    'closed alone three 2% to 525': (('closed',), (), (1, 4, 6), 0.02, 525.0),
    'closed turn + all 1% to 0': (('closed',), (TURN,), ALL, 0.01, 0.0),
    'both alone three 1% to 0': (('stat', 'closed'), (), (1, 4, 6), 0.01, 0.0),
    'both latency + all 1% to 525': (('stat', 'closed'), (LATENCY,), ALL, 0.01, 525.0),
    'control clean': (('stat',), (), (), 0.0, 0.0),
    'control clean closed': (('closed',), (), (), 0.0, 0.0),
    'control ceiling 500': (('stat',), (CEILING,), (), 0.0, 0.0),
    'control gain': (('stat',), (GAIN,), (), 0.0, 0.0),
    'control spread law': (('stat',), (SPREAD,), (), 0.0, 0.0),
}


def run(name: str, replicates: int) -> str:
    kinds, others, sensors, rate, value = CASES[name]
    recs = []
    for i, kind in enumerate(kinds):
        turn = [e for e in others if e.name == 'actuator_turn_error']
        effects = others if kind == 'closed' else tuple(e for e in others if e not in turn)
        rec = recording('closed' if kind == 'closed' else 'stat', effects, seed=5 + i)
        recs.append(drop(rec, sensors, rate, value, seed=11 + i) if sensors else rec)
    start = time.process_time()
    result = diagnose.diagnose(recs, diagnose.Options(config=CONFIG, replicates=replicates))
    cpu = time.process_time() - start
    sat = next(e for e in result.effects if e['name'] == 'saturation_quantization')
    p = sat['parameters']
    has = bool(p and p.get('dropout', 0) > 0)
    chosen = [s['name'] for s in result.compound.steps] if result.compound else []
    chosen_drop = any(s['name'] == 'saturation_quantization'
                      and s['parameters'].get('dropout', 0) > 0
                      for s in (result.compound.steps if result.compound else []))
    found = (f"dropout {p['dropout']:.4f} to {p['dropout_value']:g} on {sat['sensors']}"
             if has else 'no dropout')
    extra = f" low {p['low']:g} high {p['high']:g} step {p['step']:g}" if p else ''
    return (f'{name:32s} fitted: {found}{extra}; top {result.top_effect}; '
            f'chosen {chosen} (dropout in set: {chosen_drop}); {cpu:.1f} s CPU')


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--only', action='append', default=None)
    ap.add_argument('--replicates', type=int, default=40)
    ap.add_argument('--samples', type=int, default=60, help='per heading and condition')
    ap.add_argument('--episodes', type=int, default=24, help='closed-loop episodes')
    args = ap.parse_args(argv)
    SIZE.update(samples=args.samples, episodes=args.episodes)
    for name in args.only or CASES:
        print(run(name, args.replicates), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
