"""Outside blind benchmark of the gap diagnosis (prints figures; not a test).

    python benchmark/blind_outside.py [--cases 28] [--seed 0] [--quick] [--jobs 1]
        [--khepera-noise 'PATH/TO/khepera-noise'] [--diagnosis-shift N] [--work DIR]
        [--out FILE.json]

A second generator, written from scratch: it shares no code with the project's
effect models or the first blind benchmark, and draws hidden effects in shapes
outside the fitted families (see benchmark/outside/ and
docs/blind-benchmark.md).  Each case writes one recording as a user with a
real robot would, runs ``khepera-noise diagnose`` on it as a subprocess (any
checkout: --khepera-noise), and scores the answer against the hidden truth.
"""
from __future__ import annotations

import argparse
import json
import os
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from outside.cases import NAMES, draw_cases  # noqa: E402
from outside.record import make_recording   # noqa: E402
from outside.score import score_case         # noqa: E402

TARGETS = {'single_top1': 0.9, 'location_right': 0.9, 'compound_recall': 0.8,
           'compound_precision': 0.8, 'single_median_shrink': 0.8,
           'compound_median_shrink': 0.8}


def default_command() -> str:
    here = Path(sys.executable).with_name('khepera-noise')
    return str(here) if here.exists() else (shutil.which('khepera-noise') or 'khepera-noise')


def diagnose(command: list[str], recording: Path, out: Path, seed: int, replicates: int,
             timeout: float) -> tuple[dict | None, str, float]:
    start = time.perf_counter()
    try:
        proc = subprocess.run(command + ['diagnose', str(recording), '--out', str(out),
                                         '--no-figures', '--seed', str(seed),
                                         '--replicates', str(replicates)],
                              capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return None, f'timeout after {timeout:.0f} s', time.perf_counter() - start
    took = time.perf_counter() - start
    if proc.returncode != 0:
        lines = proc.stderr.strip().splitlines() or ['(no output)']
        frames = [ln.strip() for ln in lines if ln.strip().startswith('File ')]
        where = f' (at {frames[-1]})' if frames else ''
        return None, f'exit {proc.returncode}: {lines[-1]}{where}', took
    return json.loads((out / 'diagnosis.json').read_text()), '', took


def run_case(case, args, command, work: Path) -> dict:
    folder = work / f'case_{case["id"]:03d}'
    folder.mkdir(parents=True, exist_ok=True)
    path = make_recording(case, args.quick, folder)
    diag, error, took = diagnose(command, path, folder / 'diagnosis',
                                 case['seed'] + args.diagnosis_shift, args.replicates,
                                 args.timeout)
    result = {'id': case['id'], 'kind': case['kind'], 'protocol': case['protocol'],
              'effects': [e.describe() for e in case['effects']], 'error': error,
              'seconds': round(took, 2)}
    result.update(score_case(case, diag))
    if diag is not None:
        result['combined'] = diag.get('combined')
    return result


def summarise(results: list[dict]) -> dict:
    singles = [r for r in results if r['kind'] == 'single']
    compounds = [r for r in results if r['kind'] == 'compound']
    controls = [r for r in results if r['kind'] == 'control']
    located = [r['location'] for r in singles if r['location'] is not None]

    def frac(xs):
        return sum(map(bool, xs)) / len(xs) if xs else None

    def median(xs):
        xs = [x for x in xs if x is not None]
        return statistics.median(xs) if xs else None

    by_name = {}
    for name in NAMES:
        rs = [r for r in singles if r['truth'] == [name]]
        if rs:
            by_name[name] = {
                'cases': len(rs), 'top1': frac([r['top1'] for r in rs]),
                'location': frac([r['location'] for r in rs if r['location'] is not None]),
                'median_shrink': median([r['shrink'] for r in rs]),
                'answers': sorted({str(r['top_effect']) for r in rs})}
    return {
        'single_cases': len(singles), 'compound_cases': len(compounds),
        'control_cases': len(controls),
        'single_top1': frac([r['top1'] for r in singles]),
        'location_right': frac(located), 'location_scored': len(located),
        'compound_recall': statistics.mean([r['recall'] for r in compounds]) if compounds
        else None,
        'compound_precision': statistics.mean([r['precision'] for r in compounds])
        if compounds else None,
        'single_median_shrink': median([r['shrink'] for r in singles]),
        'compound_median_shrink': median([r['shrink'] for r in compounds]),
        'controls_none': frac([r['top1'] for r in controls]),
        'errors': sum(1 for r in results if r['error']),
        'compound_set_from': sorted({str(r['predicted_from']) for r in compounds}),
        'by_name': by_name}


def print_table(s: dict) -> None:
    def pct(v):
        return '   n/a' if v is None else f'{100 * v:5.0f}%'

    def num(v):
        return '  n/a' if v is None else f'{v:5.2f}'

    print('\nmetric                     measured  target')
    rows = (('single top-1', 'single_top1', pct), ('location right', 'location_right', pct),
            ('compound recall', 'compound_recall', pct),
            ('compound precision', 'compound_precision', pct),
            ('single median shrink', 'single_median_shrink', num),
            ('compound median shrink', 'compound_median_shrink', num))
    for label, key, fmt in rows:
        v, target = s[key], TARGETS[key]
        mark = '' if v is None else ('  ok' if v >= target else '  below')
        print(f'{label:26s} {fmt(v):>8s}  {fmt(target):>6s}{mark}')
    print(f"controls answered none     {pct(s['controls_none']):>8s}   "
          f"({s['control_cases']} cases)")
    print(f"cases: {s['single_cases']} single, {s['compound_cases']} compound, "
          f"{s['errors']} diagnosis errors; compound set read from {s['compound_set_from']}")
    print('\nsingle cases by effect       n  top-1  location  shrink  answers')
    for name, b in s['by_name'].items():
        print(f"{name:27s} {b['cases']:2d} {pct(b['top1'])} {pct(b['location']):>8s}  "
              f"{num(b['median_shrink'])}  {', '.join(b['answers'])}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--cases', type=int, default=28,
                   help='single + compound cases (60/40); 2 controls come on top')
    p.add_argument('--controls', type=int, default=2)
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--quick', action='store_true',
                   help='shorter recordings (3 headings / 10 episodes) and 50 replicates')
    p.add_argument('--replicates', type=int, default=None)
    p.add_argument('--khepera-noise', default=None, metavar='COMMAND',
                   help='the khepera-noise command to test (default: the one beside this '
                        'Python)')
    p.add_argument('--diagnosis-shift', type=int, default=0, metavar='N',
                   help="diagnose each case with its seed + N: other simulator draws, the "
                        "same recordings (a neutral change, to see what the seed is worth)")
    p.add_argument('--jobs', type=int, default=1)
    p.add_argument('--timeout', type=float, default=600.0, help='seconds per diagnosis')
    p.add_argument('--work', type=Path, default=None, help='keep recordings here')
    p.add_argument('--out', type=Path, default=Path('results/blind_outside.json'))
    args = p.parse_args(argv)
    if args.cases < 1:
        p.error(f'--cases must be at least 1, got {args.cases}')
    if args.replicates is None:
        args.replicates = 50 if args.quick else 200
    command = shlex.split(args.khepera_noise or default_command())
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    singles = -(-args.cases * 3 // 5)
    cases = draw_cases(args.seed, singles, args.cases - singles, args.controls)
    work = args.work or Path(tempfile.mkdtemp(prefix='blind_outside_'))
    shift = f', diagnosis seeds + {args.diagnosis_shift}' if args.diagnosis_shift else ''
    print(f'{len(cases)} cases (seed {args.seed}{shift}), diagnosis: {" ".join(command)}, '
          f'work: {work}', flush=True)
    results, start = [], time.perf_counter()

    def one(case):
        return run_case(case, args, command, work)

    with ThreadPoolExecutor(max(1, args.jobs)) as pool:
        for i, r in enumerate(pool.map(one, cases), 1):
            results.append(r)
            shapes = '+'.join(f"{e['name']}/{e['shape']}" for e in r['effects']) or 'none'
            verdict = (f"top {r['top_effect']} {'ok' if r['top1'] else 'wrong'}"
                       if r['kind'] != 'compound' else
                       f"set {r['predicted']} P {r['precision']:.2f} R {r['recall']:.2f}")
            shrink = '' if r['shrink'] is None else f" shrink {r['shrink']:.2f}"
            print(f"[{i}/{len(cases)}] {r['kind']:8s} {shapes}: {verdict}{shrink} "
                  f"({r['seconds']:.1f} s){' ERROR ' + r['error'] if r['error'] else ''}",
                  flush=True)
    summary = summarise(results)
    summary['wall_seconds'] = round(time.perf_counter() - start, 1)
    print_table(summary)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({'seed': args.seed, 'diagnosis_shift': args.diagnosis_shift,
                                    'quick': args.quick,
                                    'command': command, 'summary': summary,
                                    'cases': results}, indent=1, default=str))
    print(f'\nwrote {args.out} ({summary["wall_seconds"]} s)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
