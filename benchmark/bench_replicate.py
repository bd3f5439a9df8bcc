"""Wall time of the replication and the sweep, and the figures for docs/replication.md.

``python benchmark/bench_replicate.py [--skip graph,core,...] [--figures]``
runs, each from scratch in a temporary directory:

  graph    khepera-noise replicate                  (10 trials, graph + emulator)
  core     khepera-noise replicate --backend core
  ceiling  khepera-noise replicate --backend core --ceiling   (phase 2 at the full budget too)
  gceiling khepera-noise replicate --ceiling        (the same through the graph; long)
  paper    khepera-noise replicate --backend core --protocol paper
  sweep    khepera-noise sweep                      (7 realities x 4 conditions x 50 trials)

and prints each one's wall time, the CPU time of the command (a busy machine stretches
the wall time, not that), the step 1-5 means, the drop and what real training recovers
(and the ceiling arm's steps 6-7).  ``--figures`` copies the default run's figures and
the sweep's to docs/figures/replicate_*.png.  The targets (issues 12, 27): graph <= 60 s,
core <= 20 s, sweep <= 10 min.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

DOCS = Path(__file__).resolve().parent.parent / 'docs' / 'figures'
RUNS = {
    'graph': ['replicate'],
    'core': ['replicate', '--backend', 'core'],
    'ceiling': ['replicate', '--backend', 'core', '--ceiling'],
    'gceiling': ['replicate', '--ceiling'],
    'paper': ['replicate', '--backend', 'core', '--protocol', 'paper'],
    'sweep': ['sweep'],
}
TARGET_S = {'graph': 60.0, 'core': 20.0, 'sweep': 600.0}


def command() -> list[str]:
    exe = Path(sys.executable).with_name('khepera-noise')
    return [str(exe)] if exe.exists() else [sys.executable, '-m', 'khepera_noise_ros.cli']


def step_means(out: Path) -> list[float]:
    scores = defaultdict(list)
    with open(out / 'results.csv') as f:
        for row in csv.DictReader(f):
            scores[int(row['step'])].append(float(row['score']))
    return [sum(scores[s]) / len(scores[s]) for s in sorted(scores)]


def recovery_line(out: Path) -> str:
    rows = json.loads((out / 'results.json').read_text())['analysis']['recovery']['rows']
    row = rows['all conditions']
    parts = [f"{name} {row[name]['mean']:+.3f} [{row[name]['ci_low']:+.3f}, "
             f"{row[name]['ci_high']:+.3f}]" for name in ('drop', 'recovered', 'ceiling')
             if name in row]
    return '; '.join(parts)


def cpu_seconds() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--skip', default='', help='comma-separated runs to skip')
    parser.add_argument('--only', default='', help='comma-separated runs to run (default all)')
    parser.add_argument('--figures', action='store_true', help='copy figures into docs/')
    args = parser.parse_args()
    env = {**os.environ, 'ROS_AUTOMATIC_DISCOVERY_RANGE':
           os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')}
    load = os.getloadavg()[0]
    print(f'load average before: {load:.1f} on {os.cpu_count()} cores')
    with tempfile.TemporaryDirectory() as tmp:
        for name, argv in RUNS.items():
            if name in args.skip.split(',') or (args.only and name not in args.only.split(',')):
                continue
            out = Path(tmp) / name
            started, cpu = time.monotonic(), cpu_seconds()
            subprocess.run(command() + argv + ['--out', str(out), '--no-progress'], env=env,
                           check=True, stdout=subprocess.DEVNULL)
            wall, cpu = time.monotonic() - started, cpu_seconds() - cpu
            target = f' (target {TARGET_S[name]:.0f} s)' if name in TARGET_S else ''
            timing = f'{name:8s} {wall:6.1f} s wall, {cpu:6.1f} s CPU{target}'
            if name == 'sweep':
                analysis = json.loads((out / 'sweep.json').read_text())
                print(f'{timing}  {len(analysis["points"])} realities')
                for p in analysis['points']:
                    d = p['differences'].get('5% step 5', {})
                    print(f"       {p['label']:45s} 5% step 5 comb - ind "
                          f"{d.get('difference', float('nan')):+.3f} "
                          f"[{d.get('ci_low', float('nan')):+.3f}, "
                          f"{d.get('ci_high', float('nan')):+.3f}]")
                if args.figures:
                    shutil.copy(out / 'sweep_step5.png', DOCS / 'replicate_sweep_step5.png')
                continue
            means = ' '.join(f'{m:.3f}' for m in step_means(out))
            print(f'{timing}  steps 1-{len(means.split())}: {means}\n'
                  f'         {recovery_line(out)}', flush=True)
            if args.figures and name == 'graph':
                for fig in ('fig8', 'fig9', 'fig10', 'curves'):
                    shutil.copy(out / f'{fig}.png', DOCS / f'replicate_{fig}.png')
    print(f'load average after: {os.getloadavg()[0]:.1f}')


if __name__ == '__main__':
    main()
