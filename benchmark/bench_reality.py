"""Speed of the serial reality: KheperaRobots over SerialRobots on the emulator's ptys.

The emulator serves from a child process, as ``khepera-noise replicate`` runs it
(``--thread``: from a thread of this process, sharing its interpreter).  Each size runs
``--episodes`` closed-loop episodes of ``--steps`` steps (the hand-written controller)
``--repeat`` times and prints the best: batch steps per second (one step of every robot)
and robot-steps per second.  Figures, not assertions: timing depends on the machine and
its load.

    python benchmark/bench_reality.py --robots 12 40 [--thread]
"""
import argparse
import time

import numpy as np

from khepera_noise_ros.core import baseline
from khepera_noise_ros.core.task import Task
from khepera_noise_ros.reality.emulator import Emulator, EmulatorProcess
from khepera_noise_ros.reality.khepera_robot import KheperaRobots
from khepera_noise_ros.reality.world import EmulatedWorld


def episode(backend: KheperaRobots, seeds) -> None:
    readings = backend.reset(seeds, bearing_deg=np.linspace(-170, 170, len(seeds)))
    while readings is not None:
        readings = backend.step(*baseline.turn_toward_light(readings))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--robots', type=int, nargs='+', default=[12, 40])
    parser.add_argument('--episodes', type=int, default=3)
    parser.add_argument('--steps', type=int, default=60)
    parser.add_argument('--repeat', type=int, default=3)
    parser.add_argument('--thread', action='store_true',
                        help='serve from a thread of this process instead of a child process')
    args = parser.parse_args()
    for robots in args.robots:
        serving = Emulator if args.thread else EmulatorProcess
        with serving(EmulatedWorld(seed=1, robots=robots)) as emulator:
            backend = KheperaRobots.on_ports(emulator.ports, task=Task(steps=args.steps))
            episode(backend, np.arange(robots))              # opens the ports
            best = float('inf')
            for _ in range(args.repeat):
                start = time.perf_counter()
                for e in range(args.episodes):
                    episode(backend, np.arange(robots) + 1000 * (e + 1))
                best = min(best, time.perf_counter() - start)
            backend.close()
        steps = args.episodes * args.steps
        print(f'{robots:3d} robots: {steps / best:6.1f} batch steps/s, '
              f'{steps * robots / best:6.0f} robot-steps/s')


if __name__ == '__main__':
    main()
