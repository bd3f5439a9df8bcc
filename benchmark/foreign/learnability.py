"""Is a foreign robot worth testing on?  Stock controllers against robot-trained ones.

For a robot, per trial: (i) a controller evolved in the project's stock simulator (the
paper's defaults, phase-1 budget) tested on the robot, (ii) the ceiling: the same
budget run on the robot, its population seeded from that stock controller (the
replication's phase 2 at the phase-1 budget, as issue 26 measured the emulated robot),
(iii) the stock controller's fitness in the simulator, and beside them (iv) the same
budget on the robot from a random start.  Each trial's best is chosen by re-test, and
each controller is tested in the same fresh episodes.  The rule that makes a robot
learnable is fixed here, before any drawn robot was measured (docs/foreign-robots.md).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy import stats

from khepera_noise_ros.core.evaluation import CoreEvaluator, episode_fitness
from khepera_noise_ros.core.evolution import PHASE1, EAConfig, SteadyStateEA, evolve
from khepera_noise_ros.core.khepera import World
from khepera_noise_ros.core.task import Task
from khepera_noise_ros.reality.khepera_robot import InProcessRobots, KheperaRobots

from .robot import ForeignWorld

# The pre-registered rule: the ceiling beats the stock controllers by more than MARGIN with
# the 95% interval of the difference above 0, and the stock controllers' gap is the
# paper's kind (simulated above real, the paired 95% interval above 0).
MARGIN = 0.02
LEVEL = 0.95
EA = dataclasses.replace(PHASE1, best='retest', retest_episodes=5)
CAPACITY = 256            # copies of the robot driven at once


@dataclass
class RobotEvaluator:
    """(genomes, seeds) -> fitness on copies of a foreign robot, driven as the bridge
    drives a robot (``KheperaRobots``: knocks through the wheels, pulses, placements)."""

    params: dict
    seed: int
    task: Task = Task()

    def __post_init__(self):
        self.env = KheperaRobots(InProcessRobots(ForeignWorld(self.params, CAPACITY,
                                                              self.seed)), World(), self.task)

    def __call__(self, genomes, seeds) -> np.ndarray:
        return episode_fitness(self.env, genomes, seeds, CAPACITY)


def evolve_bests(evaluate, seeds: np.random.SeedSequence, trials: int,
                 ea: EAConfig = EA, start: np.ndarray | None = None) -> np.ndarray:
    """(trials, 20) bests of ``trials`` EA runs, all run as one batch; run i's population
    is seeded from ``start[i]`` when given, else random."""
    starts = [None] * trials if start is None else list(start)
    eas = [SteadyStateEA(ea, int(s), seed_genome=g)
           for s, g in zip(seeds.generate_state(trials), starts)]
    evolve(eas, evaluate)
    return np.stack([e.best_genome for e in eas])


def test(evaluate, genomes: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """(controllers,) mean fitness over the episodes ``seeds`` (the same for each)."""
    k = len(seeds)
    return evaluate(np.repeat(genomes, k, axis=0), np.tile(seeds, len(genomes))) \
        .reshape(len(genomes), k).mean(axis=1)


def episode_seeds(seq: np.random.SeedSequence, n: int) -> np.ndarray:
    return (seq.generate_state(n, np.uint64) >> np.uint64(11)).astype(np.int64)


def stock_controllers(seed: int, trials: int, ea: EAConfig = EA) -> np.ndarray:
    """Bests evolved in the stock simulator (the paper's combination noise at 5%)."""
    return evolve_bests(CoreEvaluator(), np.random.SeedSequence([seed, 0]), trials, ea)


def measure(params: dict, stock: np.ndarray, seed: int, test_episodes: int = 10,
            ea: EAConfig = EA) -> dict:
    """The arms on one robot (sim, stock, ceiling, scratch), their intervals and the
    verdict of the rule."""
    trials = len(stock)
    index = int(params['drawn'].get('index', 0))
    unit = params['unit_seed']
    ceiling = evolve_bests(RobotEvaluator(params, unit), np.random.SeedSequence(
        [seed, 1, index]), trials, ea, start=stock)
    scratch = evolve_bests(RobotEvaluator(params, unit + 1), np.random.SeedSequence(
        [seed, 3, index]), trials, ea)
    seeds = episode_seeds(np.random.SeedSequence([seed, 2, index]), test_episodes)
    on_robot = test(RobotEvaluator(params, unit + 2), np.concatenate([stock, ceiling, scratch]),
                    seeds).reshape(3, trials)
    arms = {'sim': test(CoreEvaluator(), stock, seeds), 'stock': on_robot[0],
            'ceiling': on_robot[1], 'scratch': on_robot[2]}
    result = {name: interval(values) for name, values in arms.items()}
    result['difference'] = welch(arms['ceiling'], arms['stock'])
    result['gap'] = paired(arms['sim'], arms['stock'])
    result['learnable'] = bool(result['difference']['mean'] > MARGIN
                               and result['difference']['low'] > 0.0)
    result['paper_kind'] = bool(result['gap']['low'] > 0.0)
    result['counts'] = result['learnable'] and result['paper_kind']
    result['trials'], result['test_episodes'] = trials, test_episodes
    result['values'] = {name: values.tolist() for name, values in arms.items()}
    return result


def interval(x: np.ndarray) -> dict:
    """Mean and its t interval."""
    half = stats.t.ppf(0.5 + LEVEL / 2, len(x) - 1) * x.std(ddof=1) / np.sqrt(len(x))
    return {'mean': float(x.mean()), 'low': float(x.mean() - half),
            'high': float(x.mean() + half)}


def welch(a: np.ndarray, b: np.ndarray) -> dict:
    """Mean of a - b with Welch's interval and two-sided p."""
    va, vb = a.var(ddof=1) / len(a), b.var(ddof=1) / len(b)
    df = (va + vb) ** 2 / (va ** 2 / (len(a) - 1) + vb ** 2 / (len(b) - 1))
    half = stats.t.ppf(0.5 + LEVEL / 2, df) * np.sqrt(va + vb)
    d = float(a.mean() - b.mean())
    return {'mean': d, 'low': d - half, 'high': d + half,
            'p': float(stats.ttest_ind(a, b, equal_var=False).pvalue)}


def paired(a: np.ndarray, b: np.ndarray) -> dict:
    """Mean of a - b, paired, with its t interval and two-sided p."""
    out = interval(a - b)
    out['p'] = float(stats.ttest_rel(a, b).pvalue)
    return out
