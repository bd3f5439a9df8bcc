"""The diagnosis on the two public logs of docs/real-data.md (prints figures; not a test).

    python benchmark/real_data.py [--room Occupancy_Estimation.csv] [--lab data.txt]
                                  [--seeds N] [--out FIGURES.json] [--before FIGURES.json]

The files are not in the repository (docs/real-data.md says where they are published and
which copies the page's figures come from; the SHA-256 of each input is printed, so a
figure is tied to its file).  Each is converted as the page does and diagnosed against
its references, one core, in this process:

  room         the room-occupancy file, eight channels; default, noise-free and 1 %
               independent references
  lab79        the Intel Lab log, motes 7 and 9; default, 1 % and 0.7 % independent
  lab19        motes 1-4 and 6-9, runs of 2 samples or more; the same references

Per run: the top effect, every effect's held-out reduction, the chosen compound with its
cumulative reductions, and the CPU time.  ``--out`` keeps these figures; ``--before``
prints, run by run, where an earlier ``--out`` file (another tree's) differs, and whether
each compound's held-out reduction is at least as large as before.
"""
from __future__ import annotations

import argparse
import collections
import contextlib
import hashlib
import io
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import yaml

for var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(var, '1')

from khepera_noise_ros import cli  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from paired_runs import sign_test  # noqa: E402

REFERENCES = {      # name -> the simulator's parameters (None: its defaults)
    'default': None,
    'none': {'noise_model': 'none'},
    'ind1': {'noise_model': 'independent', 'dependent_level': 0.0, 'independent_level': 0.01},
    'ind07': {'noise_model': 'independent', 'dependent_level': 0.0, 'independent_level': 0.007},
}
# recording -> (format, the file's option, the converter's arguments, references)
RUNS = {
    'room': ('room-occupancy', 'room', [], ('default', 'none', 'ind1')),
    'lab79': ('intel-lab', 'lab', ['--motes', '7', '9', '--quantity', 'light'],
              ('default', 'ind1', 'ind07')),
    'lab19': ('intel-lab', 'lab', ['--motes', '1', '2', '3', '4', '6', '7', '8', '9',
                                   '--quantity', 'light', '--min-length', '2'],
              ('default', 'ind1', 'ind07')),
}


def sha256(path: Path) -> str:
    with open(path, 'rb') as f:
        return hashlib.file_digest(f, 'sha256').hexdigest()


def quiet(argv: list[str]) -> None:
    """``khepera-noise ARGV`` in this process; its output is shown only if it fails."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        status = cli.main(argv)
    if status:
        sys.exit(f'khepera-noise {" ".join(argv)} failed ({status}):\n{out.getvalue()}')


def params_file(work: Path, reference: str) -> list[str]:
    """The ``--params`` option of ``reference``: its file, written in the nodes' format."""
    values = REFERENCES[reference]
    if values is None:
        return []
    path = work / f'{reference}.yaml'
    path.write_text(yaml.safe_dump({'/**/simulator': {'ros__parameters': values}}))
    return ['--params', str(path)]


def figures(diagnosis: dict[str, Any], cpu: float) -> dict[str, Any]:
    compound = diagnosis.get('compound') or {}
    return {'top_effect': diagnosis['top_effect'],
            'effects': {e['name']: round(e['heldout_reduction'], 6)
                        for e in diagnosis['effects']},
            'compound': [[c['name'], round(c['cumulative_reduction'], 6)]
                         for c in compound.get('chosen', [])],
            'compound_reduction': round(compound['heldout_reduction'], 6) if compound else None,
            'cpu_s': round(cpu, 2)}


def show(name: str, f: dict[str, Any]) -> None:
    chosen = ', '.join(f'{n} ({r:.3f})' for n, r in f['compound']) or 'none'
    named = '; '.join(f'{n} {r:.3f}' for n, r in f['effects'].items() if r != 0) or 'none'
    print(f'{name:14s} top {f["top_effect"]}; compound {chosen}; {f["cpu_s"]:.1f} s CPU')
    print(f'{"":14s} held-out reductions: {named}')


def over_seeds(seeds: dict[str, dict[str, Any]]) -> None:
    r = [f['compound_reduction'] for f in seeds.values() if f['compound_reduction'] is not None]
    if not r:
        print(f'{"":14s} {len(seeds)} seeds: no compound on any')
        return
    times = collections.Counter(n for f in seeds.values() for n, _ in f['compound'])
    chosen = ', '.join(f'{n} {k}' for n, k in times.most_common())
    print(f'{"":14s} {len(seeds)} seeds: a compound on {len(r)}, {min(r):.3f}-{max(r):.3f} '
          f'(mean {sum(r) / len(r):.3f}); chosen: {chosen}')


def compare(before: dict[str, Any], after: dict[str, Any]) -> None:
    print('\nagainst --before:')
    keys = ('top_effect', 'effects', 'compound')
    for name, seeds in after['runs'].items():
        was = before['runs'].get(name, {})
        shared = [s for s in seeds if s in was]
        if not shared:
            print(f'  {name}: not in --before')
            continue
        if all(was[s][k] == seeds[s][k] for s in shared for k in keys):
            print(f'  {name}: the same on {len(shared)} seed(s)')
            continue
        d = [(seeds[s]['compound_reduction'] or 0.0) - (was[s]['compound_reduction'] or 0.0)
             for s in shared]
        lower, higher = sum(x < 0 for x in d), sum(x > 0 for x in d)
        print(f'  {name}: over {len(shared)} seed(s) the compound is lower on {lower}, equal '
              f'on {len(d) - lower - higher}, higher on {higher} (sign test p = '
              f'{sign_test(lower, lower + higher):.3f}); mean change {sum(d) / len(d):+.4f}')
        if '0' in shared:
            for k in keys:
                if was['0'][k] != seeds['0'][k]:
                    print(f'      seed 0 {k}: {was["0"][k]} -> {seeds["0"][k]}')


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--room', type=Path, help='Occupancy_Estimation.csv (UCI)')
    p.add_argument('--lab', type=Path, help="data.txt (the Intel Lab log, or the page's "
                   'five-day extract)')
    p.add_argument('--seeds', type=int, default=1, help='simulator seeds 0 .. N - 1 per run')
    p.add_argument('--out', type=Path, help='write the figures here (JSON)')
    p.add_argument('--before', type=Path, help='an earlier --out to compare with')
    args = p.parse_args()
    files = {'room': args.room, 'lab': args.lab}
    if not any(files.values()):
        p.error('give --room FILE, --lab FILE or both (docs/real-data.md: where to get them)')
    if args.seeds < 1:
        p.error(f'--seeds {args.seeds}: give 1 or more')
    for option, path in files.items():
        if path is not None and not path.is_file():
            p.error(f'--{option} {path}: no such file')
    result: dict[str, Any] = {'inputs': {k: {'file': str(v), 'sha256': sha256(v)}
                                         for k, v in files.items() if v}, 'runs': {}}
    for k, v in result['inputs'].items():
        print(f'{k}: {v["file"]} sha256 {v["sha256"]}')
    with tempfile.TemporaryDirectory(prefix='real_data_') as tmp:
        work = Path(tmp)
        for rec, (fmt, option, convert_args, references) in RUNS.items():
            source = files[option]
            if source is None:
                continue
            quiet(['convert', fmt, str(source), str(work / rec)] + convert_args)
            for reference in references:
                name, seeds, params = f'{rec}/{reference}', {}, params_file(work, reference)
                for seed in range(args.seeds):
                    out = work / f'{rec}_{reference}_{seed}'
                    cpu = time.process_time()
                    quiet(['diagnose', str(work / rec), '--base', 'observed', '--no-figures',
                           '--seed', str(seed), '--out', str(out)] + params)
                    cpu = time.process_time() - cpu
                    seeds[str(seed)] = figures(
                        json.loads((out / 'diagnosis.json').read_text()), cpu)
                result['runs'][name] = seeds
                show(name, seeds['0'])
                if args.seeds > 1:
                    over_seeds(seeds)
    if args.out:
        args.out.write_text(json.dumps(result, indent=1) + '\n')
        print(f'wrote {args.out}')
    if args.before:
        compare(json.loads(args.before.read_text()), result)


if __name__ == '__main__':
    main()
