"""Lockstep throughput through the node graph against the pure core.

Prints robot-steps per second (robots x control steps per wall-clock second)
for batches of robots evaluated as one episode: by ``core.task.run`` (through
CoreEvaluator), through simulator + controller + a GraphEvaluator in one
process, and with the simulator and controller in processes of their own, and
the graph's share of the core's throughput at the same batch size.

    python benchmark/bench_graph.py [--batches 2 64 1024] [--steps 60] [--seconds 2]

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

from khepera_noise_ros.core.evaluation import CoreEvaluator  # noqa: E402
from khepera_noise_ros.core.task import Task  # noqa: E402
from khepera_noise_ros.nodes.evolution_manager import EvolutionManager  # noqa: E402
from khepera_noise_ros.nodes.graph import events_executor, local_graph  # noqa: E402


def window(evaluate, genomes, seeds, steps: int, seconds: float) -> float:
    """Robot-steps per second over repeated one-episode evaluations for ``seconds``."""
    episodes, start = 0, time.perf_counter()
    while episodes < 2 or time.perf_counter() - start < seconds:
        evaluate(genomes, seeds)
        episodes += 1
    return len(seeds) * steps * episodes / (time.perf_counter() - start)


@contextmanager
def node_processes(namespace: str, steps: int):
    """simulator and controller as processes of their own, each with its own executor."""
    args = ['--ros-args', '-r', f'__ns:={namespace}', '--log-level', 'warn']
    procs = [subprocess.Popen([sys.executable, '-m', f'khepera_noise_ros.nodes.{name}',
                               *args, *extra], env=os.environ)
             for name, extra in (('simulator', ['-p', f'steps:={steps}']), ('controller', []))]
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


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--batches', type=int, nargs='+', default=[2, 64, 1024])
    parser.add_argument('--steps', type=int, default=60)
    parser.add_argument('--seconds', type=float, default=1.0, help='per measuring window')
    parser.add_argument('--rounds', type=int, default=3,
                        help='windows per figure, interleaved; each figure is the best')
    args = parser.parse_args(argv)

    context = Context()
    rclpy.init(context=context, args=['--ros-args', '--log-level', 'warn'])
    best: dict[tuple[str, int], float] = {}
    try:
        with node_processes('/bench_split', args.steps), \
                local_graph(context, simulator={'steps': args.steps}, namespace='/bench_one',
                            thread=False, bearings=False,
                            executor_class=events_executor) as graph:
            split = EvolutionManager(context=context, namespace='/bench_split')
            graph.executor.add_node(split)
            split.evaluator.executor = graph.executor
            evaluators = {'core': CoreEvaluator(task=Task(steps=args.steps)),
                          'one process': graph.evaluator, '3 processes': split.evaluator}
            graph.evaluator.wait_ready(30)
            split.evaluator.wait_ready(60)
            for batch in args.batches:
                rng = np.random.default_rng(batch)
                genomes = rng.uniform(-1, 1, (batch, 20))
                seeds = rng.integers(0, 2 ** 53, batch)
                for name, evaluate in evaluators.items():
                    evaluate(genomes, seeds)                            # warm up
                for _ in range(args.rounds):       # interleaved: all share the same load
                    for name, evaluate in evaluators.items():
                        rate = window(evaluate, genomes, seeds, args.steps, args.seconds)
                        best[name, batch] = max(best.get((name, batch), 0.0), rate)
            graph.executor.remove_node(split)
            split.destroy_node()
    finally:
        context.try_shutdown()
    report(best, args)


def report(best: dict, args) -> None:
    print(f'lockstep robot-steps per second, episodes of {args.steps} steps, best of '
          f'{args.rounds} interleaved {args.seconds:g} s windows ({os.cpu_count()} CPUs)')
    print(f"{'batch':>6} {'core':>11} {'one process':>12} {'ratio':>6} "
          f"{'3 processes':>12} {'ratio':>6}")
    for b in args.batches:
        core, one, split = (best[name, b] for name in ('core', 'one process', '3 processes'))
        print(f'{b:>6} {core:>11.0f} {one:>12.0f} {one / core:>6.1%} '
              f'{split:>12.0f} {split / core:>6.1%}')


if __name__ == '__main__':
    main()
