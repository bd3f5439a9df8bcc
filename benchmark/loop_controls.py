"""Controls for the closed-loop noise statistics (prints figures; not a test).

    python benchmark/loop_controls.py [--seeds 10] [--first 0] [--headings] [--jobs 1]

Each seed records a clean closed-loop-only run (25 episodes; the emulated robot with
only a sensor latency, or only a turn error, alternately) and diagnoses it.  A chosen set
other than the one loop effect is a false sensor effect.
"""
from __future__ import annotations

import argparse
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

os.environ.setdefault('OMP_NUM_THREADS', '1')
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

import blind_gap  # noqa: E402
from khepera_noise_ros.core.noise import NoiseModel  # noqa: E402
from khepera_noise_ros.gap import diagnose  # noqa: E402
from khepera_noise_ros.gap.simconfig import SimConfig  # noqa: E402
from khepera_noise_ros.reality import effects as emu  # noqa: E402

EPISODES = 25


def case(seed: int) -> tuple[str, emu.EffectsConfig]:
    """(the loop effect's name, the robot's configuration) of control ``seed``."""
    rng = np.random.default_rng(seed)
    base = emu.EffectsConfig.none(blind_gap.SENSOR_NOISE)
    if seed % 2 == 0:
        name = 'sensor_latency'
        settings = {'strength': int(rng.integers(1, 4)), 'location': blind_gap.RING}
    else:
        name = 'actuator_turn_error'
        settings = {'scale': float(rng.choice([0.75, 1.3])), 'strength': 0.1}
    return name, base.only(name, **{name: settings})


def run(job) -> tuple:
    seed, genome, headings = job
    name, config = case(seed)
    world = blind_gap.robot(config, 1000 + seed)
    rec = blind_gap.record_closed_loop(world, genome, seed=seed, episodes=EPISODES,
                                       headings=headings)
    options = diagnose.Options(config=SimConfig(noise=NoiseModel.independent_only(
        blind_gap.SENSOR_NOISE)), remainder=False, seed=seed)
    out = diagnose.diagnose([rec], options).to_json()
    comp = out.get('compound')
    chosen = [c['name'] for c in comp['chosen']] if comp else [out['top_effect']]
    return seed, name, chosen


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--seeds', type=int, default=10)
    p.add_argument('--first', type=int, default=0)
    p.add_argument('--headings', action='store_true', help='keep the headings')
    p.add_argument('--jobs', type=int, default=1)
    args = p.parse_args(argv)
    if args.seeds < 1 or args.jobs < 1:
        p.error(f'--seeds and --jobs must be >= 1, got {args.seeds}, {args.jobs}')
    genome = blind_gap.evolved_genome(0)
    jobs = [(s, genome, args.headings) for s in range(args.first, args.first + args.seeds)]
    false = 0
    with ProcessPoolExecutor(args.jobs) as pool:
        for seed, name, chosen in pool.map(run, jobs):
            extra = [c for c in chosen if c != name]
            false += bool(extra)
            print(f"{'ok ' if not extra else 'XX '}seed {seed}: {name} -> {'+'.join(chosen)}",
                  flush=True)
    print(f'controls {args.seeds}, with a false sensor effect {false}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
