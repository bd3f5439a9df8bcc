"""The transfer experiment, re-run with the fitted effect (the paper's steps 1-3).

Controllers are evolved in the simulator as configured ("before") and in the
simulator with the fitted effect added ("after"), ``trials`` runs each; each
run's best genome is tested in the simulator it was evolved in and in
reality.  The fitness gap of a run is simulated minus real test fitness; an
effect that captures what reality does shrinks it.  Reality is any callable
``(genomes (n, 20), seeds (n,)) -> fitness (n,)``: the emulator, or a robot
behind the hardware bridge.  The gaps before and after, and the real fitness
before and after, are compared with Welch's two-sided t-test.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import stats as sps

from ..core import evolution, network
from ..core.khepera import World
from ..core.task import step_fitness
from ..effects.simulate import EffectEpisodes
from ..simconfig import SimConfig

Reality = Callable[[np.ndarray, np.ndarray], np.ndarray]


def fitness(env, genomes, seeds) -> np.ndarray:
    """Mean step fitness of one episode per genome on ``env``: anything with the
    ``core.task.Episodes`` interface (the simulator, or robots behind ``KheperaRobots``)."""
    weights = network.unpack(genomes)
    readings = env.reset(np.asarray(seeds, np.int64))
    total = np.zeros(len(seeds))
    steps = 0
    while readings is not None:
        direction, power = network.act(weights, readings)
        total += step_fitness(readings, power)
        steps += 1
        readings = env.step(direction, power)
    return total / max(steps, 1)


@dataclass
class SimEvaluator:
    """(genomes, seeds) -> fitness in the simulator with effects: one episode per genome."""

    config: SimConfig
    world: World
    effects: tuple = ()

    def __call__(self, genomes, seeds) -> np.ndarray:
        env = EffectEpisodes(self.world, self.config.noise, self.config.task,
                             tuple(self.config.effects) + tuple(self.effects))
        return fitness(env, genomes, seeds)


def run(config: SimConfig, world: World, effects, reality: Reality, trials: int = 5,
        ea: evolution.EAConfig = evolution.PHASE1, test_episodes: int = 10,
        seed: int = 0) -> dict:
    """Evolve before/after, test both in reality; the ``transfer`` block of diagnosis.json."""
    if trials < 2:
        raise ValueError(f'the transfer t-test needs at least 2 trials, got {trials}')
    seeds = np.random.SeedSequence(seed)
    arms = {}
    for arm, extra, s in zip(('before', 'after'), ((), tuple(effects)), seeds.spawn(2)):
        evaluate = SimEvaluator(config, world, extra)
        ea_seeds, test = s.spawn(2)
        eas = [evolution.SteadyStateEA(ea, int(x)) for x in ea_seeds.generate_state(trials)]
        evolution.evolve(eas, evaluate)
        genomes = np.repeat(np.stack([e.best_genome for e in eas]), test_episodes, axis=0)
        episode_seeds = (test.generate_state(trials * test_episodes, np.uint64)
                         >> np.uint64(11)).astype(np.int64)
        sim = evaluate(genomes, episode_seeds).reshape(trials, test_episodes).mean(axis=1)
        real = np.asarray(reality(genomes, episode_seeds), np.float64) \
            .reshape(trials, test_episodes).mean(axis=1)
        arms[arm] = {'sim': sim, 'real': real, 'gap': sim - real}
    gap = sps.ttest_ind(arms['before']['gap'], arms['after']['gap'], equal_var=False)
    real = sps.ttest_ind(arms['after']['real'], arms['before']['real'], equal_var=False)
    return {
        'fitness_gap_before': float(arms['before']['gap'].mean()),
        'fitness_gap_after': float(arms['after']['gap'].mean()),
        'trials': trials,
        'test': "Welch's t-test, two-sided",
        'gap_t': _finite(gap.statistic), 'gap_p': _finite(gap.pvalue),
        'real_fitness_before': float(arms['before']['real'].mean()),
        'real_fitness_after': float(arms['after']['real'].mean()),
        'real_t': _finite(real.statistic), 'real_p': _finite(real.pvalue),
        'sim_fitness_before': float(arms['before']['sim'].mean()),
        'sim_fitness_after': float(arms['after']['sim'].mean()),
        'ea': dataclasses.asdict(ea), 'test_episodes': test_episodes,
    }


def _finite(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None
