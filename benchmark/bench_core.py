"""Robot-steps per second of the pure core, on one core (not a test: prints figures).

    python benchmark/bench_core.py [--batches 1 64 1024 16384] [--seconds 2]

A robot-step is one control step of one robot: 8 noisy readings, the 6-2-2
network's turn, the turn applied and the step's fitness.  'batch seed' draws the
batch's randomness from one generator; 'robot seeds' gives every robot its own
counter-based stream (what evolution uses).  'python loop' is the reference a
researcher would write without this project: one robot at a time, plain Python.
Rates are per CPU-second of this process (time.process_time), so that other
work on a shared machine does not count against them.
"""
from __future__ import annotations

import argparse
import math
import os
import random
import time

os.environ.setdefault('OMP_NUM_THREADS', '1')   # one core, as the targets say

import numpy as np  # noqa: E402

from khepera_noise_ros.core import network, task  # noqa: E402
from khepera_noise_ros.core.khepera import SENSOR_ANGLES_DEG, World  # noqa: E402


def core_rate(batch: int, seconds: float, per_robot: bool) -> float:
    genomes = np.random.default_rng(0).uniform(-1, 1, (batch, network.GENES))
    weights = network.unpack(genomes)

    def policy(r):
        return network.act(weights, r)
    episodes, start = 0, time.process_time()
    while time.process_time() - start < seconds or episodes < 2:
        seed = np.arange(batch) + episodes * batch if per_robot else episodes
        task.run(policy, seed, robots=batch)
        episodes += 1
    return episodes * batch * task.Task.steps / (time.process_time() - start)


def python_loop_rate(seconds: float) -> float:
    """One robot, one step at a time, with math and random: no numpy, no batching."""
    w = World()
    genome = [random.uniform(-1, 1) for _ in range(20)]
    rng = random.Random(0)
    sig = (lambda x: 1 / (1 + math.exp(-x)))
    steps, start, bearing = 0, time.process_time(), 0.0
    while time.process_time() - start < seconds:
        if steps % 5 == 0:
            bearing += rng.uniform(-30, 30)
        readings = []
        for angle in SENSOR_ANGLES_DEG:
            a = abs((bearing - angle + 180) % 360 - 180)
            base = w.ambient - (math.cos(math.radians(1.5 * a)) * (w.reach_mm - w.lamp_distance_mm)
                                / w.reach_mm * w.gain if a < 60 else 0)
            base = round(max(base, w.floor))
            noise = int(2 * 0.02 * base * rng.random() - 0.02 * base)
            readings.append(min(max(base + noise, 0), 525))
        x = [1 - s / 525 for s in readings[:6]]
        h = [sig(sum(x[i] * genome[2 * i + j] for i in range(6)) + genome[16 + j])
             for j in range(2)]
        o = [sig(sum(h[j] * genome[12 + 2 * j + k] for j in range(2)) + genome[18 + k])
             for k in range(2)]
        direction, power = (-1 if o[0] < 0.5 else 1), min(int(o[1] * 10), 9)
        left, right = sum(readings[0:3]) / 3, sum(readings[3:6]) / 3
        _ = (1 - abs(left - right) / 525) * (1 - (readings[2] + readings[3]) / 1050) * (power > 0)
        bearing += direction * power * w.deg_per_power
        steps += 1
    return steps / (time.process_time() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--batches', type=int, nargs='+', default=[1, 64, 1024, 16384])
    parser.add_argument('--seconds', type=float, default=2.0)
    args = parser.parse_args()
    reference = python_loop_rate(args.seconds)
    print(f'python loop (1 robot)       {reference:>12,.0f} robot-steps/s')
    print(f'{"batch":>6} {"batch seed":>14} {"robot seeds":>14} {"vs python loop":>15}')
    for b in args.batches:
        fast = core_rate(b, args.seconds, per_robot=False)
        seeded = core_rate(b, args.seconds, per_robot=True)
        print(f'{b:>6} {fast:>14,.0f} {seeded:>14,.0f} {fast / reference:>14.0f}x', flush=True)


if __name__ == '__main__':
    main()
