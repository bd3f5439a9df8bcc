"""Evaluating genomes in the core: the in-process counterpart of the node graph.

An evaluator is any callable ``(genomes (n, 20), seeds (n,)) -> fitness (n,)``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import numpy.typing as npt

from . import network, task
from .khepera import World
from .noise import NoiseModel
from .task import Trace


class Episodic(Protocol):
    """What runs episodes step by step: ``task.Episodes`` and its subclasses, robots
    behind ``KheperaRobots``; None from ``step`` when the episodes end."""

    def reset(self, seed: npt.ArrayLike) -> np.ndarray | None: ...

    def step(self, direction: npt.ArrayLike, power: npt.ArrayLike) -> np.ndarray | None: ...


def episode_fitness(env: Episodic, genomes: npt.ArrayLike, seeds: npt.ArrayLike,
                    capacity: int | None = None) -> np.ndarray:
    """Mean step fitness of one episode per genome on ``env`` (the simulator with effects,
    the emulated or a foreign robot behind ``KheperaRobots``), ``capacity`` episodes at a
    time (all at once without)."""
    genomes, seeds = np.asarray(genomes), np.asarray(seeds, np.int64)
    if capacity is not None and len(seeds) > capacity:
        return np.concatenate([episode_fitness(env, genomes[lo:lo + capacity],
                                               seeds[lo:lo + capacity])
                               for lo in range(0, len(seeds), capacity)])
    weights = network.unpack(genomes)
    readings = env.reset(seeds)
    total = np.zeros(len(seeds))
    steps = 0
    while readings is not None:
        direction, power = network.act(weights, readings)
        total += task.step_fitness(readings, power)
        steps += 1
        readings = env.step(direction, power)
    out: np.ndarray = total / max(steps, 1)
    return out


@dataclass
class CoreEvaluator:
    """One episode per genome in this process, each from its own seed's stream (so a
    genome's fitness does not depend on the rest of the batch).

    Args:
        world, noise, task: the episode's setting.
    """

    world: World = field(default_factory=World)
    noise: NoiseModel = field(default_factory=NoiseModel)
    task: task.Task = field(default_factory=task.Task)

    def __call__(self, genomes: npt.ArrayLike, seeds: npt.ArrayLike) -> np.ndarray:
        """Score one episode per genome.

        Args:
            genomes: (n, 20) genomes.
            seeds: (n,) integer episode seeds.

        Returns:
            (n,) float64 fitness.
        """
        weights = network.unpack(genomes)
        return task.run(lambda r: network.act(weights, r), np.asarray(seeds, np.int64),
                        world=self.world, noise=self.noise, task=self.task).astype(np.float64)

    def trace(self, genomes: npt.ArrayLike, seeds: npt.ArrayLike) -> Trace:
        """The per-step record of the episodes ``__call__`` scores.

        Args:
            genomes, seeds: as for ``__call__``.

        Returns:
            A ``task.Trace`` with arrays (steps, n, ...).
        """
        weights = network.unpack(genomes)
        return task.run(lambda r: network.act(weights, r), np.asarray(seeds, np.int64),
                        world=self.world, noise=self.noise, task=self.task, trace=True)
