"""Why did training on the emulated robot gain nothing, and what robot recovers?

``python benchmark/learnable_gap.py [--trials 12] [--episodes 20] [--part why,grid,new]``
(about 310 s of CPU on this machine; docs/calibration.md holds its tables).

The replication's steps 3-5 on a set of emulated robots, in process (the core
simulator, the emulator's world).  Phase-1 bests evolved in simulation under the
paper's 5% independent noise (one model only: which model transfers better is the
comparison under test, and this study never looks at it) are tested on each robot
(step 3), trained on it with the paper's phase 2 (5 generations of 10) and with the
full budget (50 generations of 25: the ceiling arm), and tested again (step 5).
Beside the steps, for each robot:

- **re-evaluated**: step 5 after phase 2 with both members re-evaluated in every
  tournament (``fitness: reevaluate``), against stored fitnesses that can be lucky;
- **ceiling**: the best of the full-budget runs' step 5: what the EA can reach at all;
- **reliability** of one episode: the share of a single episode's variance that is the
  difference between controllers, over phase 2's start population (the seed's mutants,
  each tested on every test episode);
- **tournament right**: how often one episode each ranks two members of that start
  population as their true means (over the test episodes) do;
- **mutants better**: the share of the start population whose true mean beats the seed's,
  and **best mutant**: the best one's true mean less the seed's.

Every number compares a robot with the simulator, or phase 2 with phase 1: the
calibration targets of the paper's section 4.4 (a drop at step 3, real training
recovering most of it), never a noise model against another.

Parts: ``why`` (the previous default, v1, its effects one at a time and together),
``grid`` (the candidate effects and sizes tried for the new default) and ``new`` (the
new default, its effects one at a time, other units of the same make).
"""
from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy import stats

from khepera_noise_ros.core import network, task
from khepera_noise_ros.core.evolution import EAConfig, SteadyStateEA, evolve
from khepera_noise_ros.core.khepera import World
from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.experiment.protocol import play
from khepera_noise_ros.reality.effects import EffectsConfig
from khepera_noise_ros.reality.khepera_robot import InProcessRobots, KheperaRobots
from khepera_noise_ros.reality.world import EmulatedWorld

IND5 = NoiseModel.independent_only(0.05)
PHASE1 = EAConfig(best='retest')
PHASE2 = EAConfig(population=10, generations=5, best='retest')
FULL = EAConfig(population=25, generations=50, best='retest')
TEST_SEED = 7_000_000
CONFIG = Path(__file__).resolve().parents[1] / 'config'


@dataclass(frozen=True)
class Robot:
    """An emulated robot of the study: its effects, and what else differs from the
    simulator (a lamp the simulator gets wrong, a task without knocks)."""

    effects: EffectsConfig
    lamp: dict = dataclasses.field(default_factory=dict)      # World fields in reality
    task: dict = dataclasses.field(default_factory=dict)      # Task fields, both worlds


def why() -> dict[str, Robot]:
    """The previous default (v1) and its parts."""
    v1 = EffectsConfig.load(CONFIG / 'emulator_v1.yaml')
    lat, cal = {'sensor_latency': {'enabled': False}}, {'sensor_gain_offset': {'enabled': False}}
    out = {
        'v1: the previous default': v1,
        'v1 without latency': v1.replace(**lat),
        'v1 without calibration': v1.replace(**cal),
        'v1 without latency and calibration': v1.replace(**lat, **cal),
        'only latency (one whole step)': v1.only('sensor_latency'),
        'only calibration (10%, offset sd 10, unit 1)': v1.only('sensor_gain_offset'),
        'only latency, two steps': v1.only('sensor_latency', sensor_latency={'strength': 2}),
        'no effect, 1% sensor noise': EffectsConfig.none(v1.sensor_noise),
    }
    out = {k: Robot(v) for k, v in out.items()}
    out['v1 in a task without knocks'] = Robot(v1, task={'perturbation_deg': 0.0})
    return out


def grid() -> dict[str, Robot]:
    """Candidates for the new default: v1's sensors without its whole step of latency,
    with other effects a Khepera has, at several sizes."""
    v1 = EffectsConfig.load(CONFIG / 'emulator_v1.yaml')
    cal5 = {'sensor_gain_offset': {'strength': 0.05, 'offset_sd': 5.0}}
    base = v1.replace(sensor_latency={'strength': 0, 'fraction': 0.25}, **cal5)
    out = {}
    for fraction in (0.25, 0.5):
        out[f'v1, latency {fraction} of a step instead of one'] = Robot(
            v1.replace(sensor_latency={'strength': 0, 'fraction': fraction}))
    out['v1 without latency, calibration 5%, offset sd 5'] = Robot(
        v1.replace(sensor_latency={'enabled': False}, **cal5))
    for scale in (1.4, 1.8):
        out[f'turn scale {scale}'] = Robot(base.replace(actuator_turn_error={'scale': scale}))
    out['turn slip 40%'] = Robot(base.replace(actuator_turn_error={'strength': 0.4}))
    out['converter step 16'] = Robot(base.replace(
        saturation_quantization={'enabled': True, 'strength': 16.0}))
    for half in (40.0, 45.0):
        out[f'sensor cone {half:g} deg (the simulator: 60)'] = Robot(
            base, lamp={'half_angle_deg': half})
    for dead in (2.0, 3.0, 4.0):
        for asym in (0.0, 0.2, 0.3, 0.4):
            out[f'dead band {dead:g} deg, asymmetry {asym:g}'] = Robot(
                base.replace(actuator_turn_error={'dead_band': dead, 'asymmetry': asym}))
    out['dead band 3, asymmetry 0.3, calibration 10%, offset sd 10'] = Robot(base.replace(
        sensor_gain_offset={'strength': 0.1, 'offset_sd': 10.0},
        actuator_turn_error={'dead_band': 3.0, 'asymmetry': 0.3}))
    return out


def new() -> dict[str, Robot]:
    """The new default, each of its gap effects alone, and other units of the same make."""
    robot = EffectsConfig.real_robot()
    sensors = ('intensity_dependent_noise', 'correlated_noise', 'temporal_drift')
    out = {'the default (config/emulator.yaml)': robot}
    for name in ('sensor_gain_offset', 'sensor_latency', 'actuator_turn_error'):
        out[f'without {name}'] = robot.replace(**{name: {'enabled': False}})
        out[f'only {name}'] = robot.only(name)
    out['only the sensor noise (flicker, groups, drift)'] = robot.only(*sensors)
    wheels = robot.actuator_turn_error
    out['wheels without the dead band'] = robot.replace(actuator_turn_error={'dead_band': 0.0})
    out['wheels without the asymmetry'] = robot.replace(actuator_turn_error={'asymmetry': 0.0})
    out['wheels turning the other way further'] = robot.replace(
        actuator_turn_error={'asymmetry': -wheels.asymmetry})
    for unit in range(2, 9):
        out[f'unit {unit}'] = robot.replace(sensor_gain_offset={'unit_seed': unit})
    return {k: Robot(v) for k, v in out.items()}


PARTS = {'why': why, 'grid': grid, 'new': new}


# --- evaluation ----------------------------------------------------------------------

def sim_evaluator(world: World, episode: task.Task, noise: NoiseModel = IND5):
    def evaluate(genomes, seeds):
        w = network.unpack(genomes)
        return task.run(lambda r: network.act(w, r), [int(s) for s in seeds], len(seeds),
                        world, noise, episode).astype(np.float64)
    return evaluate


def real_evaluator(robot: Robot, world: World, episode: task.Task, capacity: int = 500,
                   seed: int = 1):
    """Episodes on one emulated world of ``capacity`` robots, like the replication's."""
    lamp = dataclasses.replace(world, **robot.lamp)
    emulated = EmulatedWorld(robot.effects, seed=seed, robots=capacity, geometry=lamp,
                             start_bearing_deg=0.0)
    bodies = KheperaRobots(InProcessRobots(emulated), world, episode)

    def evaluate(genomes, seeds):
        return np.concatenate([play(bodies, genomes[i:i + capacity], seeds[i:i + capacity])[0]
                               for i in range(0, len(seeds), capacity)])
    return evaluate


def test(genomes, episodes: int, evaluate, seed: int = TEST_SEED) -> np.ndarray:
    """(controllers, episodes) fitness, every controller on the same episode seeds."""
    g = np.repeat(np.asarray(genomes), episodes, axis=0)
    seeds = np.tile(np.arange(episodes, dtype=np.int64) + seed, len(genomes))
    return np.asarray(evaluate(g, seeds)).reshape(len(genomes), episodes)


def phase1_bests(world, episode, trials: int) -> np.ndarray:
    eas = [SteadyStateEA(PHASE1, seed=1000 + t) for t in range(trials)]
    evolve(eas, sim_evaluator(world, episode))
    return np.array([ea.best_genome for ea in eas])


def phase2(genomes, config: EAConfig, evaluate, seed: int = 2000) -> np.ndarray:
    eas = [SteadyStateEA(config, seed=seed + t, seed_genome=g) for t, g in enumerate(genomes)]
    evolve(eas, evaluate)
    return np.array([ea.best_genome for ea in eas])


def paired_ci(x) -> tuple[float, float, float]:
    x = np.asarray(x, np.float64).ravel()
    half = float(stats.t.ppf(0.975, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size))
    return float(x.mean()), float(x.mean()) - half, float(x.mean()) + half


def start_population(genomes, evaluate, episodes: int, mutants: int = 10, seed: int = 3000):
    """What one episode says about phase 2's start population (the seed's mutants):
    (reliability, tournament right, mutants better, best mutant's gain), means over seeds."""
    rng = np.random.default_rng(seed)
    out = []
    for g in genomes:
        pop = np.vstack([g, g + rng.uniform(-1.0, 1.0, (mutants, g.size))])
        f = test(pop, episodes, evaluate)
        means = f.mean(axis=1)
        within = f[1:].var(axis=1, ddof=1).mean()
        between = max(means[1:].var(ddof=1) - within / episodes, 0.0)
        out.append((between / (between + within), _tournament_right(f[1:], means[1:]),
                    np.mean(means[1:] > means[0]), means[1:].max() - means[0]))
    return tuple(float(v) for v in np.mean(out, axis=0))


def _tournament_right(f: np.ndarray, means: np.ndarray) -> float:
    """P(one episode of i beats one of j, on other episodes | i's true mean is higher)."""
    right = []
    n = f.shape[1]
    shift = np.roll(np.arange(n), 1)            # episode e of one against e-1 of the other
    for i in range(len(f)):
        for j in range(len(f)):
            if means[i] > means[j]:
                right.append(np.mean(f[i] > f[j, shift]) + 0.5 * np.mean(f[i] == f[j, shift]))
    return float(np.mean(right))


# --- the study -----------------------------------------------------------------------

HEAD = ('emulated robot', 'step 3', 'drop (2 - 3)', 'step 5', 'recovered (5 - 3)',
        'step 5 re-evaluated', 'step 5 full budget', 'full - step 3 [95% CI]', 'ceiling',
        'reliability', 'tournament right', 'mutants better', 'best mutant')


def study(robots: dict[str, Robot], trials: int, episodes: int, out=sys.stdout) -> list:
    world, base_task = World(), task.Task()
    started = time.monotonic()
    bests = phase1_bests(world, base_task, trials)
    step2 = test(bests, episodes, sim_evaluator(world, base_task)).mean(axis=1)
    print(f'{trials} phase-1 bests (5% independent noise); step 2 (the simulation test, '
          f'{episodes} episodes each): {step2.mean():.3f}\n', file=out)
    print('| ' + ' | '.join(HEAD) + ' |\n|' + ' --- |' * len(HEAD), file=out)
    rows = []
    for name, robot in robots.items():
        episode = dataclasses.replace(base_task, **robot.task)
        s2 = step2 if not robot.task else \
            test(bests, episodes, sim_evaluator(world, episode)).mean(axis=1)
        real = real_evaluator(robot, world, episode)
        s3 = test(bests, episodes, real).mean(axis=1)
        s5 = test(phase2(bests, PHASE2, real), episodes, real).mean(axis=1)
        again = dataclasses.replace(PHASE2, fitness='reevaluate')
        s5r = test(phase2(bests, again, real), episodes, real).mean(axis=1)
        s5f = test(phase2(bests, FULL, real), episodes, real).mean(axis=1)
        full, low, high = paired_ci(s5f - s3)
        start = start_population(bests, real, episodes)
        drop = s2.mean() - s3.mean()
        row = {'robot': name, 'step2': s2.mean(), 'step3': s3.mean(), 'step5': s5.mean(),
               'step5_reevaluated': s5r.mean(), 'step5_full': s5f.mean(), 'full_ci': (low, high),
               'ceiling': s5f.max(), 'start': start}
        rows.append(row)
        cells = [name, f'{s3.mean():.3f}', f'{drop:+.3f}', f'{s5.mean():.3f}',
                 _share(s5.mean() - s3.mean(), drop), f'{s5r.mean():.3f}', f'{s5f.mean():.3f}',
                 f'{full:+.3f} [{low:+.3f}, {high:+.3f}]', f'{s5f.max():.3f}',
                 f'{start[0]:.2f}', f'{start[1]:.0%}', f'{start[2]:.0%}', f'{start[3]:+.3f}']
        print('| ' + ' | '.join(cells) + ' |', file=out, flush=True)
    print(f'\n({time.monotonic() - started:.0f} s)\n', file=out)
    return rows


def _share(part: float, whole: float) -> str:
    return f'{part:+.3f} ({part / whole:.0%})' if whole > 0.01 else f'{part:+.3f}'


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--trials', type=int, default=12, help='phase-1 bests (trials)')
    parser.add_argument('--episodes', type=int, default=20, help='test episodes per controller')
    parser.add_argument('--part', default='why,grid,new',
                        help=f'comma-separated parts, from {", ".join(PARTS)}')
    parser.add_argument('--robots', help='only these robots of the parts (comma-separated)')
    args = parser.parse_args()
    parts = [p.strip() for p in args.part.split(',') if p.strip()]
    unknown = [p for p in parts if p not in PARTS]
    if unknown or args.trials < 2 or args.episodes < 2:
        sys.exit(f'--part must name parts from {list(PARTS)} (got {unknown}), and --trials '
                 f'and --episodes must be >= 2')
    for part in parts:
        robots = PARTS[part]()
        if args.robots:
            robots = {k: v for k, v in robots.items() if k in args.robots.split(',')}
        print(f'## {part}\n')
        study(robots, args.trials, args.episodes)


if __name__ == '__main__':
    main()
