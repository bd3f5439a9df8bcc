"""Lockstep throughput through the node graph against the pure core.

Prints robot-steps per second (robots x control steps per wall-clock second)
for batches of robots evaluated as one episode per worker, and each figure's
share of the core's throughput at the same batch size:

  core           ``core.task.run`` through CoreEvaluator, in this process
  one process    simulator + controller + a GraphEvaluator on one executor here
  3 processes    the simulator and the controller in processes of their own
  N pairs        N worker_pair processes (simulator + controller each), the batch
                 split across them by a GraphEvaluator here

Every graph is first checked to give the core's fitness.  The windows are
interleaved: each round measures every configuration once, one after the
other, so a round's figures share the machine's load.  The ratio is taken
within each round (a configuration's rate over the core's in the same round)
and the median over the rounds is printed, with the lowest and highest: on a
shared machine whose speed drifts, that is steadier than a ratio of two best
windows taken at different moments.  A second table gives the CPUs each
process kept busy during its best window (this process, which is the
manager, first), from /proc.

    python benchmark/bench_graph.py [--batches 2 64 1024] [--pairs 1 2 4] [--seconds 1]

DDS stays on this machine (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) and on
ROS_DOMAIN_ID (default: one picked from the process id).
"""
from __future__ import annotations

import argparse
from contextlib import contextmanager
import os
import signal
import subprocess
import sys
import time

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))

import numpy as np  # noqa: E402
import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.node import Node  # noqa: E402

from khepera_noise_ros import lifeline  # noqa: E402
from khepera_noise_ros.core.evaluation import CoreEvaluator  # noqa: E402
from khepera_noise_ros.core.task import Task  # noqa: E402
from khepera_noise_ros.nodes.graph import GraphEvaluator  # noqa: E402
from khepera_noise_ros.nodes.local_graph import local_graph  # noqa: E402
from khepera_noise_ros.nodes.runtime import events_executor  # noqa: E402


def cpu_seconds(pids: list[int]) -> list[float]:
    """CPU time used so far by this process and by each of ``pids``."""
    def used(pid: int) -> float:
        fields = open(f'/proc/{pid}/stat').read().rsplit(')', 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')
    return [time.process_time()] + [used(pid) for pid in pids]


def window(evaluate, genomes, seeds, steps: int, seconds: float,
           pids: list[int]) -> tuple[float, list[float]]:
    """Robot-steps per second over repeated one-batch evaluations for ``seconds``, and the
    CPUs busy meanwhile: this process (the manager), then each of ``pids``."""
    episodes, start, cpu = 0, time.perf_counter(), cpu_seconds(pids)
    while episodes < 2 or time.perf_counter() - start < seconds:
        evaluate(genomes, seeds)
        episodes += 1
    wall = time.perf_counter() - start
    return len(seeds) * steps * episodes / wall, [
        (b - a) / wall for a, b in zip(cpu, cpu_seconds(pids))]


@contextmanager
def processes(commands: list[list[str]]):
    """Node processes (``-m`` module and arguments), stopped with SIGINT at the end."""
    procs = [lifeline.popen([sys.executable, '-m', *c, '--log-level', 'warn'],
                            sig=signal.SIGTERM, env=os.environ) for c in commands]
    try:
        yield procs
    finally:
        for proc in procs:
            proc.send_signal(signal.SIGINT)
        for proc in procs:
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()


def commands(steps: int, pairs: list[int]) -> list[list[str]]:
    """The separate simulator and controller in /split, and the worker pairs of each
    configuration in /pN_i."""
    def node(module: str, ns: str) -> list[str]:
        return [f'khepera_noise_ros.nodes.{module}', '--ros-args', '-r', f'__ns:={ns}',
                '-p', f'steps:={steps}']
    return [node('simulator', '/split'), node('controller', '/split')] + [
        node('worker_pair', f'/p{n}_{i}') for n in pairs for i in range(n)]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--batches', type=int, nargs='+', default=[2, 64, 1024])
    parser.add_argument('--pairs', type=int, nargs='+', default=[1, 2, 4],
                        help='worker pair processes sharing each batch, one figure each')
    parser.add_argument('--steps', type=int, default=60)
    parser.add_argument('--seconds', type=float, default=1.0, help='per measuring window')
    parser.add_argument('--rounds', type=int, default=5,
                        help='windows per figure, interleaved; rates are the best window, '
                        'ratios the median over rounds')
    args = parser.parse_args(argv)

    context = Context()
    rclpy.init(context=context, args=['--ros-args', '--log-level', 'warn'])
    best: dict[tuple[str, int], float] = {}
    cpus: dict[tuple[str, int], list[float]] = {}      # of the best window
    ratios: dict[tuple[str, int], list[float]] = {}    # per round, against that round's core
    try:
        with processes(commands(args.steps, args.pairs)) as procs, \
                local_graph(context, simulator={'steps': args.steps}, namespace='/bench_one',
                            thread=False, trace=False,
                            executor_class=events_executor) as graph:
            clients = {'3 processes': dict(robot_namespace='/split')} | {
                f'{n} pairs': dict(workers=[f'/p{n}_{i}' for i in range(n)])
                for n in args.pairs}
            evaluators = {'core': CoreEvaluator(task=Task(steps=args.steps)),
                          'one process': graph.evaluator}
            for name, where in clients.items():
                node = Node(f'bench_{len(evaluators)}', context=context)
                graph.executor.add_node(node)
                evaluators[name] = GraphEvaluator(node, executor=graph.executor,
                                                  **where)
            for name, evaluate in evaluators.items():
                if name != 'core':
                    evaluate.wait_ready(60)
            pids, start = {'3 processes': [p.pid for p in procs[:2]]}, 2
            for n in args.pairs:                    # in the order commands() started them
                pids[f'{n} pairs'] = [p.pid for p in procs[start:start + n]]
                start += n
            measure(evaluators, pids, args, best, cpus, ratios)
    finally:
        context.try_shutdown()
    report(best, cpus, ratios, args, list(evaluators))


def measure(evaluators: dict, pids: dict, args, best: dict, cpus: dict,
            ratios: dict) -> None:
    for batch in args.batches:
        rng = np.random.default_rng(batch)
        genomes = rng.uniform(-1, 1, (batch, 20))
        seeds = rng.integers(0, 2 ** 53, batch)
        expected = evaluators['core'](genomes, seeds)
        for name, evaluate in evaluators.items():          # warm up (and fit the split)
            for _ in range(3):
                if not np.array_equal(evaluate(genomes, seeds), expected):
                    raise SystemExit(f'{name} gave other fitness than the core')
        for _ in range(args.rounds):       # interleaved: all share the same load
            rates = {}
            for name, evaluate in evaluators.items():
                rate, cpu = window(evaluate, genomes, seeds, args.steps, args.seconds,
                                   pids.get(name, []))
                rates[name] = rate
                if rate > best.get((name, batch), 0.0):
                    best[name, batch], cpus[name, batch] = rate, cpu
            for name, rate in rates.items():
                ratios.setdefault((name, batch), []).append(rate / rates['core'])


def report(best: dict, cpus: dict, ratios: dict, args, names: list[str]) -> None:
    print(f'lockstep robot-steps per second, episodes of {args.steps} steps, best of '
          f'{args.rounds} interleaved {args.seconds:g} s windows ({os.cpu_count()} CPUs); '
          'ratio: share of the core, median over the rounds [lowest-highest]')
    print(f"{'batch':>6} {'core':>9}" + ''.join(f' {n:>12} {"ratio":>17}' for n in names[1:]))
    for b in args.batches:
        print(f'{b:>6} {best["core", b]:>9.0f}' + ''.join(
            f' {best[n, b]:>12.0f} {_spread(ratios[n, b]):>17}' for n in names[1:]))
    print('CPUs busy in those windows: this process (the manager) + each node process')
    for b in args.batches:
        print(f'{b:>6} ' + '; '.join(f"{n}: {' + '.join(f'{c:.2f}' for c in cpus[n, b])}"
                                     for n in names))


def _spread(values: list[float]) -> str:
    return (f'{np.median(values):.1%} [{min(values) * 100:.0f}-{max(values) * 100:.0f}]')


if __name__ == '__main__':
    main()
