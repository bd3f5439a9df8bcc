"""A small evolution in the core, the reference the node tests hold a graph run to: a graph
run with the same settings and seeds must give exactly its numbers."""
from __future__ import annotations

from typing import Any

from ..core import evolution
from ..core.evaluation import CoreEvaluator
from ..core.task import Task

STEPS = 15
CONFIG = evolution.EAConfig(population=5, generations=3)
SEED, TRIALS = 7, 2


def core_run(seed: int = SEED) -> tuple[list[evolution.SteadyStateEA], list[int]]:
    """The uninterrupted evolution in the core, and the number of generations complete in
    every trial after each batch."""
    eas = [evolution.SteadyStateEA(CONFIG, seed + i) for i in range(TRIALS)]
    done: list[int] = []
    evolution.evolve(eas, CoreEvaluator(task=Task(steps=STEPS)),
                     progress=lambda eas: done.append(min(len(ea.history) for ea in eas)))
    return eas, done


def assert_same_evolution(record: dict[str, Any], eas: list[evolution.SteadyStateEA]) -> None:
    """The manager's results ``record`` is the core's evolution ``eas``, number for number."""
    assert record['best_genome'] == max(eas, key=lambda ea: ea.best_fitness).best_genome.tolist()
    for trial, ea in zip(record['trials'], eas):
        assert trial['best_genome'] == ea.best_genome.tolist()
        assert trial['best_fitness'] == ea.best_fitness
        assert trial['best_generation'] == ea.best_generation
        assert trial['history'] == [vars(g) for g in ea.history]
