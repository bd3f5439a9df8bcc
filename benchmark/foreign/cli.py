"""Foreign Kheperas: draw them, serve them on pseudo-terminals, measure their learnability.

    python benchmark/foreign_robots.py draw [--seed 26] [--count 10] [--first 0]
    python benchmark/foreign_robots.py serve ROBOT [--robots N] [--link PREFIX]
    python benchmark/foreign_robots.py learnability [ROBOT ...] [--trials 10]
        [--test-episodes 10] [--seed 26] [--out benchmark/foreign/learnability.json]
    python benchmark/foreign_robots.py list [--learnable]

ROBOT is a name in benchmark/foreign/robots (foreign_03) or a parameter file.  The code
in benchmark/foreign shares nothing with what fits a simulator to a robot
(docs/foreign-robots.md).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from . import learnability, params
from .draw import draw_robot

HERE = Path(__file__).resolve().parent
ROBOTS = HERE / 'robots'
RESULTS = HERE / 'learnability.json'


def robot_path(name: str) -> Path:
    """A robot's file from its name or path."""
    path = Path(name)
    if path.suffix in ('.yaml', '.yml', '.json') or path.exists():
        return path
    path = ROBOTS / f'{name}.yaml'
    if not path.exists():
        known = ', '.join(p.stem for p in sorted(ROBOTS.glob('*.yaml'))) or 'none'
        raise ValueError(f'no foreign robot {name!r}; known: {known}')
    return path


def drawn() -> list[Path]:
    return sorted(ROBOTS.glob('foreign_*.yaml'))


def benchmark_robots(results: Path = RESULTS) -> list[str]:
    """The robots that pass the pre-registered rule in the committed measurement."""
    data = json.loads(results.read_text())
    return [name for name, r in data['robots'].items() if r['counts']]


def cmd_draw(args) -> int:
    ROBOTS.mkdir(parents=True, exist_ok=True)
    for index in range(args.first, args.first + args.count):
        p = draw_robot(args.seed, index)
        print(f'wrote {params.save(p, ROBOTS / (p["name"] + ".yaml"))}')
    return 0


def cmd_serve(args) -> int:
    from foreign.serve import serve
    return serve(params.load(robot_path(args.robot)), args.robots, args.seed, args.link,
                 args.condition)


def cmd_list(args) -> int:
    names = benchmark_robots() if args.learnable else [p.stem for p in drawn()]
    print('\n'.join(names))
    return 0


def row(name: str, r: dict) -> str:
    def arm(a):
        return f"{a['mean']:.3f} [{a['low']:.3f}, {a['high']:.3f}]"
    d = r['difference']
    verdict = 'yes' if r['counts'] else ('no' if r['paper_kind'] else 'no (gap not sim > real)')
    return (f"| {name} | {arm(r['sim'])} | {arm(r['stock'])} | {arm(r['ceiling'])} | "
            f"{d['mean']:+.3f} [{d['low']:+.3f}, {d['high']:+.3f}], p {d['p']:.2g} | "
            f"{arm(r['scratch'])} | {verdict} |")


HEADER = ('| robot | sim (stock ctrl.) | stock on robot | ceiling (robot-trained) | '
          'ceiling - stock [95% CI], p | from scratch on robot | learnable |\n'
          '| --- | --- | --- | --- | --- | --- | --- |')


def cmd_learnability(args) -> int:
    paths = [robot_path(n) for n in args.robots] or drawn()
    robots = [params.load(p) for p in paths]
    if args.trials < 2 or args.test_episodes < 1:
        raise ValueError(f'--trials must be >= 2 and --test-episodes >= 1, got {args.trials} '
                         f'and {args.test_episodes}')
    start = time.process_time()
    stock = learnability.stock_controllers(args.seed, args.trials)
    print(f'stock controllers: {args.trials} trials evolved in the stock simulator '
          f'({time.process_time() - start:.1f} s CPU)', file=sys.stderr, flush=True)
    results = {}
    for i, p in enumerate(robots, 1):
        t = time.process_time()
        results[p['name']] = learnability.measure(p, stock, args.seed, args.test_episodes)
        print(f'[{i}/{len(robots)}] {p["name"]}: {time.process_time() - t:.1f} s CPU',
              file=sys.stderr, flush=True)
    print(HEADER)
    for name, r in results.items():
        print(row(name, r))
    passing = [n for n, r in results.items() if r['counts']]
    print(f'\n{len(passing)} of {len(results)} robots learnable: {", ".join(passing) or "none"}'
          f' ({time.process_time() - start:.0f} s CPU)')
    if args.out:
        args.out.write_text(json.dumps({
            'seed': args.seed, 'trials': args.trials, 'test_episodes': args.test_episodes,
            'rule': f'ceiling - stock > {learnability.MARGIN} with the 95% CI above 0, and '
                    f'sim - stock (paired) with the 95% CI above 0',
            'ea': learnability.EA.__dict__, 'robots': results}, indent=1, default=float) + '\n')
        print(f'wrote {args.out}')
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest='command', required=True)
    d = sub.add_parser('draw', help='draw robots into benchmark/foreign/robots (never over one)')
    d.add_argument('--seed', type=int, default=26)
    d.add_argument('--count', type=int, default=10)
    d.add_argument('--first', type=int, default=0, help='index of the first robot drawn')
    s = sub.add_parser('serve', help='a robot on pseudo-terminals (prints the devices)')
    s.add_argument('robot')
    s.add_argument('--robots', type=int, default=1, help='copies, one device each')
    s.add_argument('--seed', type=int, default=None, help='noise seed (default: the file\'s)')
    s.add_argument('--link', metavar='PREFIX', help='also symlinks PREFIX0, PREFIX1, ...')
    s.add_argument('--condition', default='task', help='lighting until a bridge declares one')
    m = sub.add_parser('learnability', help='stock, ceiling and sim fitness per robot')
    m.add_argument('robots', nargs='*', help='robots (default: every drawn one)')
    m.add_argument('--trials', type=int, default=10)
    m.add_argument('--test-episodes', type=int, default=10)
    m.add_argument('--seed', type=int, default=26)
    m.add_argument('--out', type=Path, default=None, help='write the results as JSON')
    ls = sub.add_parser('list', help='the drawn robots, or those that count as learnable')
    ls.add_argument('--learnable', action='store_true')
    args = p.parse_args(argv)
    try:
        return {'draw': cmd_draw, 'serve': cmd_serve, 'learnability': cmd_learnability,
                'list': cmd_list}[args.command](args)
    except ValueError as exc:
        print(f'foreign_robots: {exc}', file=sys.stderr)
        return 2


if __name__ == '__main__':
    sys.exit(main())
