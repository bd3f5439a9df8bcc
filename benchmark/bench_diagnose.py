"""How long the gap diagnosis takes (prints figures; not a test).

    python benchmark/bench_diagnose.py [--repeat 1] [--skip-long] [--robot v1|default] [--profile]

Two recordings from the emulated robot with its effects (``--robot v1``, the default
here: ``EffectsConfig.real_robot_v1()``, the robot the speed targets were set on;
``default``: today's ``real_robot()``), both stationary, as ``benchmark/blind_gap.py``
records them:
  default   the blind benchmark's protocol, 60 samples per heading and condition
  long      about 36,000 samples x 8 sensors (one hour at 10 Hz)
Each is diagnosed in this process on one core (OMP/BLAS threads set to 1); the
wall and CPU time of ``gap.diagnose.diagnose`` are printed, and the compound set
found.  ``--repeat N`` diagnoses with simulator seeds 0 .. N - 1 (another seed is
another diagnosis: seed 0's does more work than seed 1's) and prints the best and each
seed's.  On a machine shared with other jobs the wall figures are pessimistic; the
CPU time of this single-threaded process is the closer measure of one core's work.
``--profile``: one more run of each under cProfile (slower), with where its time goes:
the fitters' objectives, the comparisons, and within them the replays and statistics,
each by stage (simulation, dropout repair; block sums, bootstrap table, statistics).
"""
from __future__ import annotations

import argparse
import cProfile
import math
import os
import pstats
import sys
import time
from pathlib import Path

for var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(var, '1')
sys.path.insert(0, str(Path(__file__).resolve().parent))

from blind_gap import REPEATS, SAMPLES, STATIONARY, record_stationary, robot  # noqa: E402

from khepera_noise_ros.core.noise import NoiseModel  # noqa: E402
from khepera_noise_ros.gap import diagnose  # noqa: E402
from khepera_noise_ros.simconfig import SimConfig  # noqa: E402
from khepera_noise_ros.reality.effects import EffectsConfig  # noqa: E402

LONG_SAMPLES = 36_000


ROBOTS = {'v1': EffectsConfig.real_robot_v1, 'default': EffectsConfig.real_robot}


def recording(samples: int, seed: int = 0, which: str = 'v1'):
    world = robot(ROBOTS[which](), seed)
    return record_stationary(world, STATIONARY, samples=samples, repeats=REPEATS)


def timed(rec, seed: int = 0, which: str = 'v1') -> tuple[float, diagnose.Diagnosis]:
    """The simulator is the paper's independent model at the robot's own sensor noise,
    so the gap is the robot's effects."""
    noise = ROBOTS[which]().sensor_noise
    options = diagnose.Options(config=SimConfig(noise=NoiseModel.independent_only(noise)),
                               seed=seed)
    t0, c0 = time.perf_counter(), time.process_time()
    result = diagnose.diagnose([rec], options)
    timed.cpu = time.process_time() - c0
    return time.perf_counter() - t0, result


# where a diagnosis spends its time: (label, module of the package, its functions)
WHERE = (('the fitters\' objectives', 'gap/target.py', ('_objective',)),
         ('comparisons', 'gap/target.py', ('_compare',)),
         ('  replays, dropouts repaired', 'gap/target.py', ('_replay',)),
         ('    simulating the replay', 'effects/simulate.py', ('stationary',)),
         ('    the dropout repair', 'gap/dropouts.py', ('repair',)),
         ('  statistics', 'gap/target.py', ('_stats',)),
         ('    block sums', 'gap/stationary.py', ('sums',)),
         ('    converter sums', 'gap/converter.py', ('stationary_sums',)),
         ('    bootstrap table, resampled', 'gap/bootstrap.py', ('pack', 'resampled')),
         ('    statistics from the sums', 'gap/stationary.py', ('stats',)))


def profile(rec, which: str) -> None:
    """Print the cumulative CPU of ``WHERE`` and the functions with most time of their own."""
    profiler = cProfile.Profile(time.process_time)
    profiler.runcall(timed, rec, 0, which)
    table = pstats.Stats(profiler).stats
    print('  under cProfile (slower):')
    for label, module, names in WHERE:
        rows = [v for (path, _, func), v in table.items()
                if path.endswith(os.path.join(*module.split('/'))) and func in names]
        print(f'    {label:30s} {sum(v[1] for v in rows):5d} calls '
              f'{sum(v[3] for v in rows):6.2f} s')
    own = sorted(table.items(), key=lambda kv: -kv[1][2])[:8]
    for (path, line, func), v in own:
        print(f'    own time {v[2]:5.2f} s  {func} ({Path(path).name}:{line})')


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--repeat', type=int, default=1)
    p.add_argument('--skip-long', action='store_true')
    p.add_argument('--robot', choices=sorted(ROBOTS), default='v1')
    p.add_argument('--profile', action='store_true', help='where the time goes, by cProfile')
    args = p.parse_args(argv)
    headings = sum(len(h) for h in STATIONARY.values())
    cases = [('default', SAMPLES)]
    if not args.skip_long:
        cases.append(('long', math.ceil(LONG_SAMPLES / (headings * REPEATS))))
    print('timings on a shared machine: pessimistic')
    for label, per_heading in cases:
        rec = recording(per_heading, which=args.robot)
        times, cpu = [], []
        for k in range(args.repeat):
            seconds, result = timed(rec, k, args.robot)
            times.append(seconds)
            cpu.append(timed.cpu)
        summary = result.to_json().get('compound') or {}
        chosen = [f"{c['name']} {c['cumulative_reduction']:.2f}"
                  for c in summary.get('chosen', [])]
        shrink = summary.get('heldout_reduction')
        print(f'{label:8s} {len(rec):6d} samples x {rec.channels} sensors: diagnose '
              f'{min(times):6.2f} s wall, {min(cpu):6.2f} s CPU (best of {len(times)}); '
              f'top {result.top_effect}; '
              f'compound {chosen} shrink '
              f'{"n/a" if shrink is None else f"{shrink:.2f}"}', flush=True)
        if len(cpu) > 1:     # each repeat is another simulator seed: another diagnosis
            seeds = ', '.join(f'{k}: {c:.2f} s' for k, c in enumerate(cpu))
            print(f'  CPU by simulator seed: {seeds}')
        if args.profile:
            profile(rec, args.robot)
    return 0


if __name__ == '__main__':
    sys.exit(main())
