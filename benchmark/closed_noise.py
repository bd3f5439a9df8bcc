"""Closed-loop compound cases with recorded headings (prints figures; not a test).

    python benchmark/closed_noise.py [--cases 16] [--seed 0] [--episodes 24]

Each case is a closed-loop recording of the light-centring task (``--episodes``, default 24, of 60
steps, headings kept, as from a tracked robot) made by the simulator with hidden
effects: one that acts on the turns (sensor latency of 1-2 steps on every sensor, or
a turn error) and one sensor effect (fast noise shared by a random non-adjacent pair,
a spread law, or a slow shared drift).  The diagnosis gets the recording and the plain
simulator's configuration; at the end the chosen compound set is compared with the
hidden one (recall and precision of the effect names).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault('OMP_NUM_THREADS', '1')
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))

import numpy as np  # noqa: E402

from khepera_noise_ros.gap import diagnose, replay  # noqa: E402
from khepera_noise_ros.gap import effects as fx  # noqa: E402
from test_gap_support import CONFIG, closed_loop_protocol  # noqa: E402


def draw(rng: np.random.Generator) -> list:
    if rng.random() < 0.5:
        turns = fx.SensorLatency(tuple(range(8)), int(rng.integers(1, 3)))
    else:
        turns = fx.ActuatorTurnError(float(rng.choice([0.7, 1.35])), 0.0)
    kind = rng.integers(3)
    if kind == 0:
        a = int(rng.integers(8))
        b = int((a + rng.integers(2, 7)) % 8)
        sensor = fx.CorrelatedNoise((tuple(sorted((a, b))),), float(rng.uniform(0.02, 0.04)))
    elif kind == 1:
        sensor = fx.IntensityDependentNoise(tuple(range(8)), float(rng.uniform(0.02, 0.04)),
                                            float(rng.choice([0.5, 1.0, 2.0])), 525.0, 1.0,
                                            str(rng.choice(['dark', 'bright'])), False)
    else:
        sensor = fx.TemporalDrift(tuple(range(8)), float(rng.uniform(0.02, 0.04)),
                                  float(rng.uniform(10, 40)), True)
    return [turns, sensor]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--cases', type=int, default=16)
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--episodes', type=int, default=24)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    options = diagnose.Options(config=CONFIG, replicates=60)
    hits = chosen_total = hidden_total = 0
    start = time.process_time()
    for case in range(args.cases):
        hidden = draw(rng)
        rec = replay.replay(closed_loop_protocol(args.episodes), CONFIG, hidden, seed=1000 + case)
        rec.manifest = dict(rec.manifest, source='emulator')
        out = diagnose.diagnose([rec], options).to_json()
        chosen = [c['name'] for c in (out['compound'] or {}).get('chosen', [])]
        names = {e.name for e in hidden}
        hits += len(names & set(chosen))
        chosen_total += len(chosen)
        hidden_total += len(names)
        print(f'case {case}: hidden {sorted(names)} chosen {chosen}', flush=True)
    print(f'recall {hits / hidden_total:.2f} precision {hits / max(chosen_total, 1):.2f} '
          f'({args.cases} cases, {time.process_time() - start:.0f} s CPU)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
