"""Blind benchmark of the compound diagnosis: 2-4 effects at once (prints figures; not a test).

    python benchmark/blind_compound.py [--cases 24] [--seed 0] [--jobs 1] [--cache DIR]
                                       [--hard [--loop-only [--tracked]] [--shape S]]
                                       [--only K ...] [--out FILE.json]

Each case sets 2-4 effects of the emulated robot (``reality`` effects) at once, each
at a random location and strength drawn as ``blind_gap.py`` draws a single one; every
other case (the even ones) has a closed-loop effect (sensor latency or a turn error)
among them.  The robot records a stationary and a closed-loop recording as in
``blind_gap.py``; the diagnosis gets only those and the simulator's configuration.
At the end: recall and precision of the effect set (the compound's chosen effects
against the effects set), pooled over cases, the median held-out shrink, and for
every case with a miss or a false effect the compound's ``rejected`` entry and the
held-out discrepancy of each part (stationary, closed-loop, closed-loop noise)
before any effect and after the chosen ones.  ``--cache`` keeps the recordings, so a
change to the diagnosis is measured on the same data.  ``--hard`` draws the cases of
``hard_compound.py`` instead: a strong loop effect beside weaker sensor effects;
``--loop-only`` records those cases closed-loop only (``hard_compound.loop_only``),
``--tracked`` with the headings kept in every case (20 episodes);
``--shape`` draws one sensor shape in every case (a small part beside the loop effect).

"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import pickle
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

os.environ.setdefault('OMP_NUM_THREADS', '1')
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

import blind_gap  # noqa: E402
import hard_compound  # noqa: E402
from khepera_noise_ros.core.noise import NoiseModel  # noqa: E402
from khepera_noise_ros.gap import diagnose  # noqa: E402
from khepera_noise_ros.gap.families import PARTS  # noqa: E402
from khepera_noise_ros.simconfig import SimConfig  # noqa: E402
from khepera_noise_ros.reality import effects as emu  # noqa: E402

LOOP = ('actuator_turn_error', 'sensor_latency')


def draw_compound(rng, k: int) -> tuple[list, emu.EffectsConfig, dict]:
    """(effect names, emulator configuration, truth per effect) of case ``k``."""
    size = int(rng.integers(2, 5))
    names = list(rng.choice(emu.EFFECTS, size=size, replace=False))
    if k % 2 == 0 and not set(names) & set(LOOP):
        names[int(rng.integers(0, size))] = str(rng.choice(LOOP))
    names = sorted(set(str(n) for n in names))
    base = emu.EffectsConfig.none(blind_gap.SENSOR_NOISE)
    effects, truth = {}, {}
    for name in names:
        _, config, detail = blind_gap.draw_case(rng, name)
        effects[name] = getattr(config, name)
        truth[name] = detail['settings']
    return names, dataclasses.replace(base, **effects), truth


def _recordings(k: int, rng, genome, cache: Path | None, hard: bool = False,
                loop_only: bool = False, tracked: bool = False, shape: str | None = None):
    if hard:
        seed = int(rng.integers(0, 2 ** 31))
        names, config, added, truth = hard_compound.draw(rng, seed, shape)
        how = hard_compound.plan(rng)
        if loop_only:                     # the same draws, recorded closed-loop only
            how = hard_compound.loop_only(k, seed, tracked)
        truth['recorded'] = how
    else:
        names, config, truth = draw_compound(rng, k)
        seed = int(rng.integers(0, 2 ** 31))
    tag = (('tracked' if tracked else 'loop') if loop_only else 'hard') if hard else 'case'
    tag += f'_{shape}' if shape else ''
    path = None if cache is None else cache / f'{tag}{k:03d}_{seed}.pkl'
    if path is not None and path.exists():
        return names, truth, pickle.loads(path.read_bytes())
    world = hard_compound.robot(config, added, seed) if hard else blind_gap.robot(config, seed)
    if not hard:
        how = {'stationary': True, 'headings': False}
    recordings = ([blind_gap.record_stationary(world)] if how['stationary'] else []) + \
        [blind_gap.record_closed_loop(world, genome, seed=seed, headings=how['headings'],
                                      episodes=how.get('episodes',
                                                       blind_gap.CLOSED_LOOP_EPISODES))]
    if path is not None:
        path.write_bytes(pickle.dumps(recordings))
    return names, truth, recordings


def _parts(c) -> dict:
    return {p: round(c.part(p).discrepancy, 1) for p in PARTS} if c is not None else {}


def diagnose_case(job) -> dict:
    k, names, truth, recordings, options = job
    t0 = time.perf_counter()
    result = diagnose.diagnose(recordings, dataclasses.replace(options, seed=k))
    seconds = time.perf_counter() - t0
    out = result.to_json()
    comp = out.get('compound')
    if comp is not None:
        answer = [c['name'] for c in comp['chosen']]
    else:
        answer = [] if result.top_effect == 'none' else [result.top_effect]
    after = result.compound.comparison if result.compound is not None else \
        result.held_out_after
    return {'case': k, 'truth': names, 'answer': answer, 'settings': truth,
            'shrink': comp['heldout_reduction'] if comp else 0.0,
            'rejected': comp['rejected'] if comp else None,
            'steps': [(c['name'], round(c['added_reduction'], 4), round(c['p_value'], 3),
                       c.get('counted_by'))
                      for c in comp['chosen']] if comp else [],
            'fitted': [(c['name'], c['sensors'], c['parameters']) for c in comp['chosen']]
            if comp else [],
            'parts_before': _parts(result.held_out_before), 'parts_after': _parts(after),
            'single': [(e['name'], round(e['heldout_reduction'], 3)) for e in out['effects']],
            'seconds': seconds}


def summary(rows: list[dict]) -> dict:
    hit = sum(len(set(r['truth']) & set(r['answer'])) for r in rows)
    truth = sum(len(r['truth']) for r in rows)
    answered = sum(len(r['answer']) for r in rows)
    per = {}
    for r in rows:
        for n in r['truth']:
            per.setdefault(n, [0, 0])[1] += 1
            per[n][0] += n in r['answer']
    false = {}
    for r in rows:
        for n in set(r['answer']) - set(r['truth']):
            false[n] = false.get(n, 0) + 1
    return {'cases': len(rows), 'recall': hit / max(truth, 1),
            'precision': hit / max(answered, 1),
            'exact': float(np.mean([set(r['truth']) == set(r['answer']) for r in rows])),
            'median_shrink': float(np.median([r['shrink'] for r in rows])),
            'recall_per_effect': {n: f'{a}/{b}' for n, (a, b) in sorted(per.items())},
            'false_effects': false,
            'seconds': float(sum(r['seconds'] for r in rows))}


def show(r: dict) -> None:
    missed = sorted(set(r['truth']) - set(r['answer']))
    extra = sorted(set(r['answer']) - set(r['truth']))
    mark = 'ok ' if not missed and not extra else 'XX '
    print(f"{mark}case {r['case']:3d} {'+'.join(r['truth'])} -> {'+'.join(r['answer']) or '-'}"
          f" shrink {r['shrink']:.2f} ({r['seconds']:.0f} s)", flush=True)
    if missed or extra:
        print(f"      missed {missed} false {extra}; steps {r['steps']}")
        print(f"      rejected {r['rejected']}")
        print(f"      parts before {r['parts_before']} after {r['parts_after']}")
        print(f"      single {r['single']}", flush=True)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--cases', type=int, default=24)
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--jobs', type=int, default=1)
    p.add_argument('--only', type=int, nargs='*', default=None, help='run only these cases')
    p.add_argument('--cache', type=Path, default=None, help='keep the recordings here')
    p.add_argument('--hard', action='store_true',
                   help='a strong loop effect beside 1-3 weaker sensor effects of various '
                        'shapes (benchmark/hard_compound.py)')
    p.add_argument('--loop-only', action='store_true',
                   help='with --hard: every case recorded closed-loop only (20-30 episodes, '
                        'headings kept in one case of four)')
    p.add_argument('--tracked', action='store_true',
                   help='with --loop-only: headings kept in every case (a tracked robot), '
                        '20 episodes')
    p.add_argument('--shape', choices=hard_compound.SHAPES, default=None,
                   help='with --hard: this sensor shape in every case (e.g. dropout beside '
                        'the loop effect)')
    p.add_argument('--out', type=Path, default=None, help='write the per-case results here')
    args = p.parse_args(argv)
    if (args.loop_only or args.shape) and not args.hard:
        p.error('--loop-only and --shape need --hard')
    if args.tracked and not args.loop_only:
        p.error('--tracked needs --loop-only')
    if args.jobs < 1:
        p.error(f'--jobs must be >= 1, got {args.jobs}')
    if args.cache is not None:
        args.cache.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(args.seed)
    genome = blind_gap.evolved_genome(args.seed)
    options = diagnose.Options(config=SimConfig(noise=NoiseModel.independent_only(
        blind_gap.SENSOR_NOISE)), remainder=False)
    jobs = []
    for k in range(args.cases):
        names, truth, recordings = _recordings(k, rng, genome, args.cache, args.hard,
                                               args.loop_only, args.tracked, args.shape)
        if args.only is None or k in args.only:
            jobs.append((k, names, truth, recordings, options))
    rows = []
    if args.jobs == 1:
        for job in jobs:
            rows.append(diagnose_case(job))
            show(rows[-1])
    else:
        with ProcessPoolExecutor(args.jobs) as pool:
            for row in pool.map(diagnose_case, jobs):
                rows.append(row)
                show(row)
    s = summary(rows)
    print()
    print(f"cases {s['cases']}, recall {s['recall']:.0%}, precision {s['precision']:.0%}, "
          f"set exact in {s['exact']:.0%}, median held-out shrink {s['median_shrink']:.2f}, "
          f"diagnosis {s['seconds']:.0f} s")
    print(f"recall per effect {s['recall_per_effect']}; false effects {s['false_effects']}")
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({'summary': s, 'cases': rows}, indent=1, default=float))
    return 0


if __name__ == '__main__':
    sys.exit(main())
