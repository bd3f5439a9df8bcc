"""False alarms of the rare-event statistics (dropouts, pile-ups) on recordings without them.

    python benchmark/rare_controls.py [--seeds 10] [--replicates 40] [--only NAME]

Each control is a recording made by the simulator (``test_gap_support``) from a robot
with no dropouts: clean (stationary, 2,400 samples; closed loop, 24 episodes), clean
with normal noise over 3,600 samples (the pile-up tests' protocol), a value lattice, a
real ceiling and a real floor (limits, not dropouts), a spread law, and heavy-tailed
noise (Student t with 3 degrees of freedom added by hand: a tail, not a dropout).  Per
control and seed (the recording's seed; the diagnosis's own seed is 0) it counts: a
dropout or pile-up statistic significant in ``where``, a dropout fitted
(``saturation_quantization`` with a dropout rate), a limit fitted where the robot has
none, and the top effect.
"""
from __future__ import annotations

import argparse
import copy
import dataclasses
import os
import sys
from collections import Counter
from pathlib import Path

for var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(var, '1')
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))

import numpy as np  # noqa: E402
from test_gap_support import CONDITIONS, CONFIG, closed_loop_protocol, recorded, \
    stationary_protocol  # noqa: E402

from khepera_noise_ros.core.noise import NoiseModel  # noqa: E402
from khepera_noise_ros.gap import diagnose  # noqa: E402
from khepera_noise_ros.gap import effects as fx  # noqa: E402

ALL = tuple(range(8))
NORMAL = dataclasses.replace(
    CONFIG, noise=NoiseModel.independent_only(0.02, distribution='normal'))
DIM = {k: v for k, v in CONDITIONS.items() if k != 'task'}


def heavy(rec, seed: int):
    """``rec`` with Student-t (3 dof, scale 4 readings) noise added, reflected at 0 and 525
    (clipped, the readings beyond would pile up at the range's ends: a real limit)."""
    out = copy.deepcopy(rec)
    rng = np.random.default_rng(seed + 1000)
    x = np.round(out.readings[:, :8] + 4.0 * rng.standard_t(3, (len(out), 8)))
    x = np.abs(x)
    out.readings[:, :8] = np.clip(np.where(x > 525, 1050 - x, x), 0, 525)
    return out


# name: (protocol maker, config, effects, whether the robot has a limit, edit)
CONTROLS = {
    'clean': (lambda: stationary_protocol(samples=60), CONFIG, (), False, None),
    'clean closed': (lambda: closed_loop_protocol(24), CONFIG, (), False, None),
    'clean normal 3600': (lambda: stationary_protocol(samples=150, conditions=DIM), NORMAL, (),
                          False, None),
    'lattice 4': (lambda: stationary_protocol(samples=60), CONFIG,
                  (fx.SaturationQuantization(ALL, step=4.0),), False, None),
    'ceiling 500': (lambda: stationary_protocol(samples=60), CONFIG,
                    (fx.SaturationQuantization(ALL, 0.0, 500.0),), True, None),
    'floor 250 on s2': (lambda: stationary_protocol(samples=60), CONFIG,
                        (fx.SaturationQuantization((2,), 250.0, 525.0),), True, None),
    'spread law': (lambda: stationary_protocol(samples=60), CONFIG,
                   (fx.IntensityDependentNoise(ALL, 0.04, 2.0),), False, None),
    'heavy tails': (lambda: stationary_protocol(samples=60), CONFIG, (), False, heavy),
}


def run(name: str, seed: int, replicates: int) -> dict:
    protocol, config, effects, limited, edit = CONTROLS[name]
    rec = recorded(protocol(), effects, config=config, seed=seed)
    if edit is not None:
        rec = edit(rec, seed)
    result = diagnose.diagnose([rec], diagnose.Options(config=config, replicates=replicates))
    flagged = {w['statistic'] for w in result.where if w['significant']}
    sat = next(e for e in result.effects if e['name'] == 'saturation_quantization')
    p = sat['parameters']
    return {'dropout statistic': bool(flagged & {'dropout', 'closed_loop_dropout'}),
            'pileup statistic': 'pileup' in flagged,
            'dropout fitted': bool(p and p.get('dropout', 0) > 0),
            'limit fitted': bool(p and not limited and (p['low'] > 0 or p['high'] < 525)),
            'top': result.top_effect}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seeds', type=int, default=10)
    ap.add_argument('--replicates', type=int, default=40)
    ap.add_argument('--only', action='append', default=None)
    args = ap.parse_args(argv)
    for name in args.only or CONTROLS:
        rows = [run(name, seed, args.replicates) for seed in range(args.seeds)]
        alarms = {k: sum(r[k] for r in rows) for k in rows[0] if k != 'top'}
        tops = Counter(r['top'] for r in rows)
        print(f'{name:18s} ' + ', '.join(f'{k} {v}/{len(rows)}' for k, v in alarms.items())
              + f'; top {dict(tops)}', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
