"""CPU time of one lockstep step in two source trees, timed in alternation in one process.

    python benchmark/ab_step.py OLD_TREE NEW_TREE [--robots 64 1024 16384] [--rounds 9]

A tree is a directory holding a ``khepera_noise_ros`` package (a checkout, or
``git archive REV | tar -x -C DIR``).  One step is what the nodes do with it:
pack and unpack ``light``, the controller's network, pack and unpack ``cmd_turn``,
the step's fitness and the simulator's step; ``act``, ``fitness`` and ``run`` time
``network.act``, ``task.step_fitness`` and a 60-step ``task.run`` alone.  Each
tree's arrays are used in its own orientation ((SENSORS, B) before the package
became batch-first, (B, SENSORS) after).  Alternating the trees round by round
lets both see the same load on a shared machine; medians are printed.
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys
import time

os.environ.setdefault('OMP_NUM_THREADS', '1')

import numpy as np  # noqa: E402


def load(tree: str) -> dict:
    for name in [m for m in sys.modules if m.startswith('khepera_noise_ros')]:
        del sys.modules[name]
    sys.path.insert(0, tree)
    try:
        return {n: importlib.import_module(f'khepera_noise_ros.{n}')
                for n in ('core.network', 'core.task', 'nodes.protocol')}
    finally:
        sys.path.pop(0)


def timings(m: dict, robots: int, steps: int = 200) -> dict[str, float]:
    """Microseconds per call (``run``: per episode) for one round."""
    net, task, proto = m['core.network'], m['core.task'], m['nodes.protocol']
    genomes = np.random.default_rng(0).uniform(-1, 1, (robots, net.GENES))
    weights = net.unpack(genomes)
    env = task.Episodes(task=task.Task(steps=10 ** 6))
    sensor_major = task.Episodes().reset([0, 1], 2).shape == (8, 2)   # the old orientation
    readings = env.reset(np.arange(robots), robots)
    out = {}
    start = time.process_time()
    for n in range(steps):
        light = proto.pack_light(1, n, readings.T if sensor_major else readings, raw=True)
        values = proto.unpack_light(light).values
        seen = (values.T if sensor_major else values).astype(np.float32)
        direction, power = net.act(weights, seen)
        cmd = proto.unpack_cmd_turn(proto.pack_cmd_turn(1, n, direction, power, raw=True))
        task.step_fitness(np.asarray(readings, np.float32), cmd.values[:, 1])
        readings = env.step(cmd.values[:, 0], cmd.values[:, 1])
    out['step'] = (time.process_time() - start) / steps * 1e6
    seen = np.asarray(readings, np.float32)
    start = time.process_time()
    for _ in range(steps):
        direction, power = net.act(weights, seen)
    out['act'] = (time.process_time() - start) / steps * 1e6
    start = time.process_time()
    for _ in range(steps):
        task.step_fitness(seen, power)
    out['fitness'] = (time.process_time() - start) / steps * 1e6
    start = time.process_time()
    task.run(lambda r: net.act(weights, r), np.arange(robots), robots=robots)
    out['run'] = (time.process_time() - start) * 1e6
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('old')
    parser.add_argument('new')
    parser.add_argument('--robots', type=int, nargs='+', default=[64, 1024, 16384])
    parser.add_argument('--rounds', type=int, default=9)
    args = parser.parse_args()
    trees = {'old': load(args.old), 'new': load(args.new)}
    print('median CPU microseconds (run: per 60-step episode), old -> new')
    for robots in args.robots:
        rounds: dict[tuple[str, str], list[float]] = {}
        for _ in range(args.rounds):
            for name, modules in trees.items():
                for what, us in timings(modules, robots).items():
                    rounds.setdefault((what, name), []).append(us)
        row = '  '.join(f'{what} {np.median(rounds[what, "old"]):,.1f} -> '
                        f'{np.median(rounds[what, "new"]):,.1f}'
                        for what in ('step', 'act', 'fitness', 'run'))
        print(f'{robots:>6} robots  {row}')


if __name__ == '__main__':
    main()
