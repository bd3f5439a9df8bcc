"""Does the diagnosis identify the simulator's world?  Held-out discrepancy per robot.

    python benchmark/identify.py [ROBOT ...] [--seed 0] [--episodes 40] [--out FILE.json]

ROBOT is ``emulator`` (config/emulator.yaml, the emulated robot) or a foreign robot
(``foreign_03``, benchmark/foreign/robots).  Each robot is recorded in this process
through the hardware bridge's backend (``KheperaRobots``: placements, turns in wheel
pulses, knocks made by the wheels), with the record command's protocols
(``commands/_identify``): a heading sweep in the paper's four conditions, the turn
calibration, and closed-loop episodes of a controller evolved in the stock simulator,
its headings known as an emulator reports them.  The diagnosis (the stock simulator,
``SimConfig()``) runs twice on the same recordings: with the unmodelled effects only
(the vocabulary before issue 26) and with the world model's parts too (the default).
Printed per robot: the held-out discrepancy before any effect and after each compound,
and the effects chosen (``--untracked``: headings known only at placements, as a real
Khepera records; ``--fit-noise``: against the paper's noise model fitted to the sweep, as
``khepera-noise fit`` does, instead of the stock one).  Nothing here is tuned to these
robots; they only record.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault('OMP_NUM_THREADS', '1')
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

from khepera_noise_ros.commands import _identify  # noqa: E402
from khepera_noise_ros.commands.record import named_conditions  # noqa: E402
from khepera_noise_ros.core import evolution, network  # noqa: E402
from khepera_noise_ros.core.evaluation import CoreEvaluator  # noqa: E402
from khepera_noise_ros.core.khepera import World  # noqa: E402
from khepera_noise_ros.core.task import Task  # noqa: E402
from khepera_noise_ros.effects import NAMES  # noqa: E402
from khepera_noise_ros.gap import diagnose  # noqa: E402
from khepera_noise_ros.reality.effects import EffectsConfig  # noqa: E402
from khepera_noise_ros.reality.khepera_robot import InProcessRobots, KheperaRobots  # noqa: E402
from khepera_noise_ros.reality.world import EmulatedWorld  # noqa: E402
from khepera_noise_ros.recording import FORMAT, Recording, concatenate  # noqa: E402
from khepera_noise_ros.simconfig import SimConfig  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SECTION2 = ('bulb_1ft', 'bulb_2ft', 'room_fluorescent', 'room_dark')


def world_of(name: str, seed: int):
    """The robot's world (one copy) and what it is."""
    if name == 'emulator':
        return EmulatedWorld(EffectsConfig.load(ROOT / 'config' / 'emulator.yaml'), seed=seed)
    from foreign import params
    from foreign.robot import ForeignWorld
    from foreign_robots import robot_path
    return ForeignWorld(params.load(robot_path(name)), robots=1, seed=seed)


def manifest(protocol: str, conditions: dict, **extra) -> dict:
    return {'format': FORMAT, 'source': 'emulator', 'sample_period_s': 1.0,
            'protocol': protocol, 'conditions': conditions, **extra}


def episode(env: KheperaRobots, seed: int, bearing: float | None, policy, label: str,
            number: int, heading: float | None = None) -> Recording:
    """One episode driven as the recorder drives it: each reading answered by ``policy``;
    headings as the robot reports them (``heading``: the experimenter's, fixed)."""
    readings = env.reset([seed], bearing_deg=bearing)
    rows = []
    t = 0
    while readings is not None:
        d, p = policy(readings[0])
        h = heading if heading is not None else float(env.bearing_deg[0])
        rows.append((t, h, readings[0].copy(), d, p))
        readings = env.step(np.array([d]), np.array([p]))
        t += 1
    n = len(rows)
    return Recording(np.full(n, number), np.array([r[0] for r in rows]),
                     np.array([r[1] for r in rows], float), np.full(n, label),
                     np.array([r[2] for r in rows], float).reshape(n, 8),
                     np.array([r[3] for r in rows], float), np.array([r[4] for r in rows],
                                                                     float), {})


def sweep(world, seed: int, samples: int = 10, step: float = 10.0) -> Recording:
    conditions = {c: named_conditions()[c] for c in SECTION2}
    parts, k = [], 0
    for label, params in conditions.items():
        env = KheperaRobots(InProcessRobots(world), World(**params),
                            Task(steps=samples, perturbation_deg=0.0))
        for h in _identify.sweep_headings(step, params):
            rec = episode(env, seed + k, h, lambda r: (1, 0), label, k, heading=h)
            rec.direction[:] = np.nan
            rec.power[:] = np.nan
            parts.append(rec)
            k += 1
    return concatenate(parts, manifest('stationary', conditions, sweep_step_deg=step,
                                       sweep_passes=2))


def turn_calibration(world, seed: int, rest: int = 10, repeats: int = 3) -> Recording:
    params = named_conditions()['task']
    steps = _identify.turn_steps(rest)
    env = KheperaRobots(InProcessRobots(world), World(**params),
                        Task(steps=steps, perturbation_deg=0.0))
    parts, k = [], 0
    for _ in range(repeats):
        for power in _identify.POWERS:
            parts.append(episode(env, seed + k, _identify.placement(power),
                                 _identify.turn_policy(power, rest), 'turns_task', k))
            k += 1
    return concatenate(parts, manifest('closed_loop', {'turns_task': params},
                                       calibration='turns', turn_rest=rest,
                                       task={'steps': steps, 'perturb_every': 5,
                                             'perturbation_deg': 0.0}))


def closed_loop(world, genome: np.ndarray, seed: int, episodes: int) -> Recording:
    params = named_conditions()['task']
    env = KheperaRobots(InProcessRobots(world), World(**params), Task())
    weights = network.unpack(genome[None])

    def policy(readings):
        d, p = network.act(weights, readings[None].astype(np.float32))
        return int(d[0]), int(p[0])
    parts = [episode(env, seed + k, 0.0, policy, 'task', k) for k in range(episodes)]
    return concatenate(parts, manifest('closed_loop', {'task': params},
                                       genome=[float(g) for g in genome],
                                       task={'steps': 60, 'perturb_every': 5,
                                             'perturbation_deg': 25.0}))


def stock_genome(seed: int) -> np.ndarray:
    """A controller evolved in the stock simulator (the one the recordings run)."""
    eas = [evolution.SteadyStateEA(evolution.EAConfig(population=25, generations=30), s)
           for s in np.random.SeedSequence(seed).generate_state(4)]
    evolution.evolve(eas, CoreEvaluator())
    return max(eas, key=lambda e: e.best_fitness).best_genome


def summary(result) -> dict:
    """Held-out discrepancy of the stock simulator, with the world identified, and with
    the compound beside it."""
    c, w = result.compound, result.world
    start = result.held_out_before.discrepancy if result.held_out_before else 0.0
    before = w.before if w is not None else start
    after = c.discrepancy_after if c else start
    return {'before': before, 'world': w.after if w is not None else None, 'after': after,
            'reduction': 1.0 - after / before if before > 0 else 0.0,
            'world_effects': [e.to_dict() for e in w.effects] if w is not None else [],
            'world_notes': w.notes if w is not None else {},
            'chosen': [(s['name'], s['sensors'], round(s['cumulative_reduction'], 3))
                       for s in c.steps] if c else [],
            'notes': {e['name']: e['note'] for e in result.effects}}


def untracked(rec: Recording) -> Recording:
    """As a robot that does not know its heading records: the placements' alone."""
    rec.heading_deg = np.where(rec.step == 0, rec.heading_deg, np.nan) \
        if rec.manifest.get('calibration') else np.full(len(rec), np.nan)
    return rec


def run(name: str, seed: int, episodes: int, genome: np.ndarray,
        tracked: bool = True, fit_noise: bool = False) -> dict:
    world = world_of(name, seed)
    t0 = time.process_time()
    recordings = [sweep(world, seed), turn_calibration(world, seed + 1000),
                  closed_loop(world, genome, seed + 2000, episodes)]
    if not tracked:
        recordings[1:] = [untracked(r) for r in recordings[1:]]
    out = {'robot': name, 'samples': [len(r) for r in recordings],
           'record_cpu_s': time.process_time() - t0}
    config = SimConfig()
    if fit_noise:           # the paper's model fitted to the sweep (khepera-noise fit)
        from khepera_noise_ros.experiment import noisefit
        fitted = noisefit.fit(recordings[0], config, seed, level_dependence=False)
        config = dataclasses.replace(config, noise=fitted.noise_model())
        out['noise'] = dataclasses.asdict(config.noise)
    for label, effects in (('unmodelled', NAMES), ('world', None)):
        t0 = time.process_time()
        options = diagnose.Options(config=config, seed=seed)
        if effects is not None:
            options = dataclasses.replace(options, effects=effects)
        out[label] = summary(diagnose.diagnose(recordings, options))
        out[label]['cpu_s'] = time.process_time() - t0
        o = out[label]
        world = '' if o['world'] is None else \
            f"world {[e['name'] for e in o['world_effects']]} -> {o['world']:.0f}, "
        print(f"{name} {label}: held-out discrepancy {o['before']:.0f} -> {world}"
              f"{o['after']:.0f} ({o['reduction']:.1%} removed) "
              f"{[c[0] for c in o['chosen']]} ({o['cpu_s']:.0f} s CPU)", flush=True)
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('robots', nargs='*', default=['emulator'])
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--episodes', type=int, default=40)
    p.add_argument('--untracked', action='store_true',
                   help='headings unknown but at the placements, as on a real Khepera')
    p.add_argument('--fit-noise', action='store_true',
                   help='diagnose against the paper\'s noise model fitted to the sweep')
    p.add_argument('--out', type=Path)
    args = p.parse_args(argv)
    genome = stock_genome(args.seed)
    rows = [run(r, args.seed, args.episodes, genome, not args.untracked, args.fit_noise)
            for r in args.robots]
    if args.out:
        args.out.write_text(json.dumps(rows, indent=1, default=float) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
