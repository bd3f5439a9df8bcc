"""Dump ``diagnosis.json`` of both ``bench_diagnose.py`` recordings (prints nothing else).

    python benchmark/same_answers.py OUTDIR [--skip-long] [--profile]

For speed work that must not change an answer: dump before a change, dump after,
and ``cmp`` the files (``default.json``, ``long.json``).  ``--profile`` also writes
``<label>.prof`` (cProfile) beside each dump.
"""
from __future__ import annotations

import argparse
import cProfile
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_diagnose  # noqa: E402  (sets the thread counts to 1 first)
from blind_gap import REPEATS, SAMPLES, STATIONARY  # noqa: E402

from khepera_noise_ros.files import write_json  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('outdir', type=Path)
    p.add_argument('--skip-long', action='store_true')
    p.add_argument('--profile', action='store_true')
    args = p.parse_args(argv)
    args.outdir.mkdir(parents=True, exist_ok=True)
    headings = sum(len(h) for h in STATIONARY.values())
    cases = [('default', SAMPLES)]
    if not args.skip_long:
        cases.append(('long', math.ceil(bench_diagnose.LONG_SAMPLES / (headings * REPEATS))))
    for label, per_heading in cases:
        rec = bench_diagnose.recording(per_heading)
        prof = cProfile.Profile() if args.profile else None
        c0 = time.process_time()
        if prof:
            prof.enable()
        _, result = bench_diagnose.timed(rec, 0)
        if prof:
            prof.disable()
            prof.dump_stats(str(args.outdir / f'{label}.prof'))
        cpu = time.process_time() - c0
        write_json(args.outdir / f'{label}.json', result.to_json())
        print(f'{label}: {cpu:.2f} s CPU', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
