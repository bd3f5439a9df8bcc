"""Evaluating genomes in the core: the in-process counterpart of the node graph.

An evaluator is any callable ``(genomes (n, 20), seeds (n,)) -> fitness (n,)``.
Each genome gets one episode whose randomness comes from its own seed, so a
genome's fitness does not depend on what else is in the batch; the graph's
evaluator gives the same numbers for the same seeds.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import network, task
from .khepera import World
from .noise import NoiseModel


@dataclass
class CoreEvaluator:
    world: World = field(default_factory=World)
    noise: NoiseModel = field(default_factory=NoiseModel)
    task: task.Task = field(default_factory=task.Task)

    def __call__(self, genomes, seeds) -> np.ndarray:
        weights = network.unpack(genomes)
        return task.run(lambda r: network.act(weights, r), np.asarray(seeds, np.int64),
                        world=self.world, noise=self.noise, task=self.task).astype(np.float64)

    def trace(self, genomes, seeds) -> task.Trace:
        """Per-step record of the same episodes ``__call__`` scores."""
        weights = network.unpack(genomes)
        return task.run(lambda r: network.act(weights, r), np.asarray(seeds, np.int64),
                        world=self.world, noise=self.noise, task=self.task, trace=True)
