"""Why the emulated robot's groups and turn error can be missed (prints figures).

    python benchmark/missed_effects.py [--seed 4] [--samples 240] [--episodes 120]

groups      the robot's correlated noise beside its other effects, all true: the excess
            correlation of the fast residuals (what ``fit.correlated`` clusters) within
            the true groups, and where the held-out discrepancy the groups explain lies,
            by statistic family (correlation, or the spread and value lattice).
latency     the robot with its sensor latency alone, closed loop, against the simulator
            with the true latency: the closed-loop discrepancy left when the robot's
            delay line carries the last episode's reading into the next episode's first
            (as the emulator does), and when it is refilled at each placement (a delay in
            time: the experimenter takes far longer than one sample to face the robot to
            the lamp).  What is left there is a floor beside which a turn error's share
            of the closed loop's remainder stays small.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))

import blind_gap  # noqa: E402
import emulated_set as es  # noqa: E402
import numpy as np  # noqa: E402

from khepera_noise_ros.gap import compound, groups  # noqa: E402
from khepera_noise_ros.reality.effects import EffectsConfig  # noqa: E402


def by_family(c) -> dict:
    out: dict = {}
    for k, z in zip(c.keys, c.z):
        out[k.family] = out.get(k.family, 0.0) + max(abs(z) - 2.0, 0.0) ** 2
    return out


def group_evidence(seed: int, samples: int, episodes: int) -> None:
    config = EffectsConfig.real_robot()
    recs = es.recordings(config, seed, samples, episodes)
    true = es.true_effects(config)
    rest = [e for n, e in true.items() if n != 'correlated_noise']
    pairs = [(i, j) for g in config.correlated_noise.location for i in g for j in g if i < j]
    for target, label in zip(es.parts(recs, config), ('fitting', 'held-out')):
        given = target.with_given(rest)
        without = target.compare(rest)
        z = groups.fast_evidence(given, without)
        within = [z[i, j] for i, j in pairs]
        print(f'  {label}: fast-residual excess correlation z within the true groups, the '
              f'other five given true: max {max(within):+.1f}, mean {np.mean(within):+.1f} '
              f'(clustered above {groups.THRESHOLD}); groups found: {groups.cluster(z)}')
        if label == 'held-out':
            full = target.compare(list(true.values()))
            f0, f1 = by_family(without), by_family(full)
            fams = sorted(set(f0) | set(f1), key=lambda f: f1.get(f, 0) - f0.get(f, 0))
            print(f'    the true groups take the held-out discrepancy {without.discrepancy:.0f}'
                  f' -> {full.discrepancy:.0f}; by family: ' + ', '.join(
                      f'{f} {f0.get(f, 0):.0f} -> {f1.get(f, 0):.0f}' for f in fams[:5]))


def latency_floor(seed: int, episodes: int) -> None:
    config = EffectsConfig.real_robot().only('sensor_latency')
    for refill in (False, True):
        recs = _closed_loop(config, seed, episodes, refill)
        _, b = es.parts(recs, config)
        c = b.compare(list(es.true_effects(config).values()))
        fams = sorted(by_family(c).items(), key=lambda t: -t[1])[:4]
        print(f'  delay line {"refilled at each placement" if refill else "carried over"}: '
              f'closed loop left by the true latency {compound._part(c, "closed_loop"):.0f} '
              f'(chance {compound._part_chance(c, "closed_loop"):.1f}); ' + ', '.join(
                  f'{f} {v:.0f}' for f, v in fams))


def _closed_loop(config, seed: int, episodes: int, refill: bool) -> list:
    world = es.robot(config, seed)
    reset = blind_gap.KheperaRobots.reset

    def placed(self, *args, **kwargs):
        for process in world._chain.chain:
            if refill and type(process).__name__ == 'Latency':
                process.count[:] = 0          # the next read fills the past with itself
        return reset(self, *args, **kwargs)
    blind_gap.KheperaRobots.reset = placed
    try:
        return [blind_gap.record_closed_loop(world, np.array(es.GENOME), episodes=episodes,
                                             seed=seed)]
    finally:
        blind_gap.KheperaRobots.reset = reset


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--seed', type=int, default=4)
    p.add_argument('--samples', type=int, default=240)
    p.add_argument('--episodes', type=int, default=120)
    a = p.parse_args(argv)
    print(f'seed {a.seed}: {a.samples} samples per cell, {a.episodes} closed-loop episodes')
    print('groups:')
    group_evidence(a.seed, a.samples, a.episodes)
    print('latency:')
    latency_floor(a.seed, a.episodes)
    return 0


if __name__ == '__main__':
    sys.exit(main())
