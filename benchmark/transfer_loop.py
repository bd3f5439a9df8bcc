"""The whole loop, robot by robot: record, diagnose, evolve the arms, test on the robot.

    python benchmark/transfer_loop.py [ROBOT ...] [--trials 10] [--test-episodes 10]
        [--jobs 2] [--seed 26] [--out benchmark/transfer_loop.json] [--no-progress]
        [--protocols identify|section2] [--untracked]

ROBOT is ``emulator`` (the emulated robot, config/emulator.yaml) or a foreign robot
(benchmark/foreign/robots, docs/foreign-robots.md); the default is the emulator and the
foreign robots that pass the learnability rule.  For each robot, in this process (the
core backend, no ROS), what a user with the robot attached runs
(docs/transfer.md):

1. record the heading sweep (4 conditions, every 10 degrees, two passes), the turn
   calibration and 40 closed-loop episodes driven by a controller from the stock
   simulator, one robot, one episode after another (as ``khepera-noise record --protocol
   sweep / turns / closed_loop``; ``--protocols section2``: section 2's placements, 4
   conditions x 5 headings x 60 samples, instead of the first two);
2. diagnose them with the defaults of ``khepera-noise diagnose`` and write its outputs;
3. the transfer experiment of ``diagnose --transfer-emulator`` with the ceiling
   (``experiment.transfer``): stock, independent, combination, diagnosed and
   robot-trained arms, ``--trials`` runs each, every best tested on the robot.

The stock simulator's arms do not depend on the robot: they are evolved once and shared
(the same seeds give the same controllers inside ``transfer.run``).  Robots run in
``--jobs`` processes.  Nothing here is tuned to the outcome: the robots were drawn before
this loop ran on them, and every threshold comes from the statistics (transfer_stats).
"""
from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import resource
import statistics
import sys
import time
from pathlib import Path

for var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(var, '1')
sys.path.insert(0, str(Path(__file__).resolve().parent))


from khepera_noise_ros import simconfig  # noqa: E402
from khepera_noise_ros.core.evaluation import episode_fitness  # noqa: E402
from khepera_noise_ros.core.khepera import World  # noqa: E402
from khepera_noise_ros.core.task import Task  # noqa: E402
from khepera_noise_ros.experiment import transfer, transfer_stats  # noqa: E402
from khepera_noise_ros.experiment.transfer_report import share_text  # noqa: E402
from khepera_noise_ros.experiment import diagnosis_report as report  # noqa: E402
from khepera_noise_ros.gap import diagnose  # noqa: E402
from khepera_noise_ros.reality import record as inprocess  # noqa: E402
from khepera_noise_ros.reality.effects import EffectsConfig  # noqa: E402
from khepera_noise_ros.reality.khepera_robot import InProcessRobots, KheperaRobots  # noqa: E402
from khepera_noise_ros.reality.world import EmulatedWorld  # noqa: E402

HERE = Path(__file__).resolve().parent
EMULATOR = HERE.parent / 'config' / 'emulator.yaml'
CAPACITY = 256
STAGES = ('recorded', 'diagnosed', 'transfer done')
SHARED = ('stock', 'independent', 'combination')


def world_of(name: str, copies: int, salt: int):
    """``copies`` copies of the robot ``name``, their noise streams keyed by ``salt``."""
    if name == 'emulator':
        return EmulatedWorld(EffectsConfig.load(EMULATOR), seed=salt, robots=copies,
                             start_bearing_deg=0.0)
    from foreign import params
    from foreign.cli import robot_path
    robot = params.load(robot_path(name))
    from foreign.robot import ForeignWorld
    return ForeignWorld(robot, copies, seed=robot['unit_seed'] + salt)


def reality_of(name: str, salt: int):
    env = KheperaRobots(InProcessRobots(world_of(name, CAPACITY, salt)), World(), Task())

    def evaluate(genomes, seeds):
        return episode_fitness(env, genomes, seeds, CAPACITY)
    return evaluate


def loop(name: str, shared: dict, args, out: Path, tell=None) -> dict:
    """The loop on one robot; the transfer block with what the diagnosis chose."""
    cpu = time.process_time()
    tell = tell or (lambda *a: None)
    one = InProcessRobots(world_of(name, 1, 0))
    genome = shared['stock'][0]                 # the recording's controller: a stock best
    recordings = [inprocess.stationary(one, seed=args.seed),
                  inprocess.closed_loop(one, genome, episodes=40, seed=args.seed + 1000)]
    if args.protocols == 'identify':    # the protocols that identify the world (identify.py)
        import identify
        world = world_of(name, 1, 0)
        recordings[:1] = [identify.sweep(world, args.seed),
                          identify.turn_calibration(world, args.seed + 2000)]
        if args.untracked:      # as a real Khepera records: headings at placements only
            recordings[1:] = [identify.untracked(r) for r in recordings[1:]]
    tell(name, STAGES[0])
    spent = {'record': time.process_time() - cpu}
    config = simconfig.SimConfig()
    result = diagnose.diagnose(recordings, diagnose.Options(config=config, seed=args.seed,
                                                            replicates=200))
    paths = report.write(result, out / name, config, figures=False)
    tell(name, STAGES[1])
    spent['diagnose'] = time.process_time() - cpu - spent['record']
    fitted = simconfig.load(paths['params']) if 'params' in paths else None
    outcome = transfer.run(transfer.arms(config, fitted), reality_of(name, 2),
                           args.trials, transfer.EA, args.test_episodes, args.seed,
                           ceiling=True, evolved=shared)
    block = transfer_stats.block(outcome)
    tell(name, STAGES[2])
    block['fitted'] = [e.name for e in result.fitted_effects]
    block['cpu_s'] = time.process_time() - cpu
    spent['transfer'] = block['cpu_s'] - spent['record'] - spent['diagnose']
    block['cpu_stages_s'] = spent
    return block


def _work(job):
    name, shared, args, out, queue = job
    return name, loop(name, shared, args, out, lambda *m: queue.put(m))


def row(name: str, t: dict) -> str:
    def arm(a):
        a = t['arms'].get(a) or {}
        r = a.get('real')
        return '-' if r is None else f"{r['mean']:.3f} [{r['ci_low']:.3f}, {r['ci_high']:.3f}]"
    verdict = t['verdict'] or 'no effect fitted'
    share = share_text(t).replace('share recovered ', '') if t['ceiling_clear'] \
        else 'n/a (robot-trained not clearly better)'
    return (f"| {name} | {', '.join(t['fitted']) or 'none'} | {arm('stock')} | "
            f"{arm('independent')} | {arm('diagnosed')} | {arm('robot_trained')} | "
            f"{share} | {verdict} | {'yes' if t['recommended'] else 'no'} |")


HEADER = ('| robot | fitted effects | stock (= combination) | independent | diagnosed | '
          'robot-trained | share recovered [95% CI] | diagnosed vs stock | recommended |\n'
          '| --- | --- | --- | --- | --- | --- | --- | --- | --- |')


def medians(results: dict) -> dict:
    """Medians over robots, and the counts the issue's criteria ask for."""
    diff = [t['arms']['diagnosed']['versus_stock']['difference'] for t in results.values()
            if t['arms'].get('diagnosed', {}).get('versus_stock')]
    clear = [n for n, t in results.items() if t['ceiling_clear']]
    shares = [results[n]['share_recovered'] for n in clear
              if results[n]['share_recovered'] is not None]
    verdicts = [t['verdict'] for t in results.values() if t['verdict']]

    def med(x):
        return statistics.median(x) if x else None
    return {'robots': len(results), 'diagnosed_minus_stock_median': med(diff),
            'ceiling_clear': clear, 'share_recovered_median_where_clear': med(shares),
            'verdicts': {v: verdicts.count(v) for v in transfer_stats.VERDICTS},
            'recommended': sum(bool(t['recommended']) for t in results.values())}


def _num(x, spec: str) -> str:
    return 'n/a' if x is None else format(x, spec)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('robots', nargs='*', help="'emulator' or foreign robots (default: the "
                                             'emulator and the learnable foreign robots)')
    p.add_argument('--trials', type=int, default=transfer.TRIALS)
    p.add_argument('--test-episodes', type=int, default=transfer.TEST_EPISODES)
    p.add_argument('--seed', type=int, default=26)
    p.add_argument('--jobs', type=int, default=2)
    p.add_argument('--out', type=Path, default=HERE / 'transfer_loop.json')
    p.add_argument('--diagnoses', type=Path, default=Path('results/transfer_loop'),
                   help="each robot's diagnosis.json and fitted params")
    p.add_argument('--no-progress', action='store_true')
    p.add_argument('--untracked', action='store_true',
                   help='headings known only where the robot was placed, as a real Khepera '
                        'records (turns inferred through the sweep)')
    p.add_argument('--protocols', choices=('identify', 'section2'), default='identify',
                   help='identify: the heading sweep and the turn calibration (record '
                        '--protocol sweep / turns) beside the closed loop; section2: the '
                        'paper\'s placements instead (no world identified)')
    args = p.parse_args(argv)
    from foreign.cli import benchmark_robots
    names = args.robots or ['emulator'] + benchmark_robots()
    wall, cpu = time.monotonic(), time.process_time()
    config = simconfig.SimConfig()
    shared = {name: transfer.evolve(transfer.SimEvaluator(c), transfer.seeds_for(
        args.seed, name, 'evolve'), args.trials, transfer.EA)
        for name, c in transfer.arms(config, None).items() if name != 'combination'}
    shared['combination'] = shared['stock']   # the stock simulator is the paper's combination
    print(f'stock simulator arms: {time.process_time() - cpu:.1f} s CPU', file=sys.stderr)
    from tqdm import tqdm
    bar = tqdm(total=len(names) * len(STAGES), unit='stage', file=sys.stderr,
               disable=args.no_progress, dynamic_ncols=True)
    results = {}
    with mp.Manager() as manager, mp.get_context('fork').Pool(args.jobs) as pool:
        queue = manager.Queue()
        jobs = pool.imap_unordered(_work, [(n, shared, args, args.diagnoses, queue)
                                           for n in names])
        pending = len(names)
        while pending:
            while not queue.empty():
                robot, stage = queue.get()
                bar.set_description_str(f'{robot}: {stage}', refresh=False)
                bar.update(1)
            try:
                name, block = jobs.next(timeout=0.5)
            except mp.TimeoutError:
                continue
            results[name] = block
            pending -= 1
        while not queue.empty():
            queue.get()
            bar.update(1)
    bar.close()
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    total_cpu = time.process_time() - cpu + children.ru_utime + children.ru_stime
    elapsed = time.monotonic() - wall
    results = {n: results[n] for n in names}
    print(HEADER)
    for name, t in results.items():
        print(row(name, t))
    summary = medians(results)
    print(f"\nmedians over {summary['robots']} robots: diagnosed - stock "
          f"{_num(summary['diagnosed_minus_stock_median'], '+.3f')}; share recovered "
          f"{_num(summary['share_recovered_median_where_clear'], '.2f')} over the "
          f"{len(summary['ceiling_clear'])} robots whose robot-trained controllers are "
          f"clearly better; verdicts {summary['verdicts']}; recommended "
          f"{summary['recommended']} of {summary['robots']}")
    stages = {k: sum(t['cpu_stages_s'][k] for t in results.values())
              for k in ('record', 'diagnose', 'transfer')}
    print(f'{elapsed:.0f} s wall, {total_cpu:.0f} s CPU ({args.jobs} jobs, '
          f'{os.cpu_count()} cores; CPU by stage over the robots: '
          + ', '.join(f'{k} {v:.0f} s' for k, v in stages.items()) + ')')
    args.out.write_text(json.dumps({
        'seed': args.seed, 'protocols': args.protocols, 'untracked': args.untracked,
        'trials': args.trials,
        'test_episodes': args.test_episodes,
        'wall_s': elapsed, 'cpu_s': total_cpu, 'jobs': args.jobs, 'summary': summary,
        'robots': results}, indent=1, default=float) + '\n')
    print(f'wrote {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
