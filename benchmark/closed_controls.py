"""Controls of the closed-loop-only diagnosis: no sensor effect at all (prints figures; not
a test).

    python benchmark/closed_controls.py [--seeds 10] [--first 0] [--loops none latency turn]
                                        [--episodes 30] [--headings] [--jobs 1]

For each seed and each loop setting (none; a sensor latency of 1-3 samples; a turn error),
the emulated robot with no sensor effect records closed-loop only (``--episodes``, no
headings unless ``--headings``, as most cases of ``blind_compound.py --hard
--loop-only``), and the diagnosis's answer is printed.  A sensor effect named (a lattice,
a limit, dropouts: ``saturation_quantization``; a spread law, shared noise; any other) is
a false one.  Last: the false effects per name.
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
from khepera_noise_ros.simconfig import SimConfig  # noqa: E402
from khepera_noise_ros.reality import effects as emu  # noqa: E402

LOOPS = {'none': (), 'latency': ('sensor_latency',), 'turn': ('actuator_turn_error',)}


def config(loop: str, rng) -> emu.EffectsConfig:
    base = emu.EffectsConfig.none(blind_gap.SENSOR_NOISE)
    settings = {}
    if loop == 'latency':
        settings['sensor_latency'] = {'strength': int(rng.integers(1, 4)),
                                      'location': blind_gap.RING}
    if loop == 'turn':
        scale = rng.uniform(0.6, 0.85) if rng.random() < 0.5 else rng.uniform(1.15, 1.4)
        settings['actuator_turn_error'] = {'scale': float(scale),
                                           'strength': float(rng.uniform(0.0, 0.3))}
    return base.only(*settings, **settings) if settings else base


def run(job) -> tuple:
    seed, loop, genome, episodes, headings = job
    rng = np.random.default_rng(seed)
    world = blind_gap.robot(config(loop, rng), seed)
    rec = blind_gap.record_closed_loop(world, genome, seed=seed, episodes=episodes,
                                       headings=headings)
    options = diagnose.Options(config=SimConfig(noise=NoiseModel.independent_only(
        blind_gap.SENSOR_NOISE)), remainder=False, seed=seed)
    out = diagnose.diagnose([rec], options).to_json()
    comp = out.get('compound')
    answer = [c['name'] for c in comp['chosen']] if comp else \
        ([] if out['top_effect'] == 'none' else [out['top_effect']])
    return seed, loop, answer


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--seeds', type=int, default=10)
    p.add_argument('--first', type=int, default=0, help='the first seed')
    p.add_argument('--loops', nargs='*', default=list(LOOPS), choices=list(LOOPS))
    p.add_argument('--episodes', type=int, default=30)
    p.add_argument('--headings', action='store_true', help='keep the headings (a tracked robot)')
    p.add_argument('--jobs', type=int, default=1)
    args = p.parse_args(argv)
    if min(args.seeds, args.jobs, args.episodes) < 1:
        p.error(f'--seeds, --episodes and --jobs must be >= 1, got {args.seeds}, '
                f'{args.episodes} and {args.jobs}')
    genome = blind_gap.evolved_genome(0)        # the controller of blind_compound.py's seed 0
    jobs = [(seed, loop, genome, args.episodes, args.headings) for loop in args.loops
            for seed in range(args.first, args.first + args.seeds)]
    false: dict = {}
    with ProcessPoolExecutor(args.jobs) as pool:
        for seed, loop, answer in pool.map(run, jobs):
            extra = [a for a in answer if a not in LOOPS[loop]]
            for name in extra:
                false.setdefault(f'{loop}: {name}', 0)
                false[f'{loop}: {name}'] += 1
            print(f"{'ok' if not extra else 'XX'} seed {seed} {loop}: {'+'.join(answer) or '-'}",
                  flush=True)
    print(f'\nfalse effects over {len(jobs)} recordings: {false or "none"}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
