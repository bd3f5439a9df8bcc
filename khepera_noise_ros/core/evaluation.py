"""Evaluating genomes in the core: the in-process counterpart of the node graph.

An evaluator is any callable ``(genomes (n, 20), seeds (n,)) -> fitness (n,)``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from . import network, task
from .khepera import World
from .noise import NoiseModel
from .task import Trace


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
