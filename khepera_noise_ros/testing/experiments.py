"""The replication at a tiny scale, in process, and a synthetic set of its results: what the
experiment tests run, analyse and report on."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..experiment import config as settings, report
from ..experiment.protocol import STEPS, Backends, Experiment, chunked, chunked_trace, \
    core_simulate, play
from ..experiment.store import Store
from ..reality.khepera_robot import InProcessRobots, KheperaRobots
from ..reality.world import EmulatedWorld

TINY = {'trials': 2, 'test_episodes': 2, 'phase1': {'population': 4, 'generations': 3},
        'phase2': {'population': 3, 'generations': 2}, 'task': {'steps': 12},
        'reality': {'robots': 8}, 'backend': {'simulation': 'core', 'reality': 'world'}}

# Synthetic step scores per condition: 5% combination clearly better at step 5.
MEANS = {'5% combination': (0.78, 0.77, 0.60, 0.74, 0.80),
         '5% independent': (0.78, 0.77, 0.55, 0.72, 0.76),
         '10% combination': (0.77, 0.76, 0.62, 0.73, 0.77),
         '10% independent': (0.77, 0.76, 0.61, 0.73, 0.75)}
GENERATIONS = {'5% combination': 30, '5% independent': 44, '10% combination': 40,
               '10% independent': 41}


def tiny(**changes: Any) -> settings.ReplicateConfig:
    """The replication's settings at a scale that runs in a second, with ``changes``."""
    return settings.load(overrides=settings.merge(TINY, changes, 'test')
                         if changes else TINY)


class Spy:
    """Wraps an evaluator and remembers every batch it was given."""

    def __init__(self, evaluate: Callable[[Any, Any], Any]):
        self.evaluate = evaluate
        self.batches: list[tuple[np.ndarray, np.ndarray]] = []

    def __call__(self, genomes: Any, seeds: Any) -> Any:
        self.batches.append((np.array(genomes), np.array(seeds)))
        return self.evaluate(genomes, seeds)

    @property
    def episodes(self) -> int:
        return sum(len(s) for _, s in self.batches)


def backends(config: settings.ReplicateConfig, reality_spy: bool = True,
             simulate: Any = None, traced: bool = False) -> Backends:
    """The core simulator and the emulated world in process, as ``--backend core``."""
    world = EmulatedWorld(config.effects, seed=config.reality['seed'],
                          robots=config.reality['robots'], geometry=config.world)
    robots = KheperaRobots(InProcessRobots(world), config.world, config.task)
    capacity = config.reality['robots']
    reality = chunked(lambda g, s: play(robots, g, s)[0], capacity)
    trace = chunked_trace(lambda g, s: play(robots, g, s)[1], capacity) if traced else None
    noise = {c.key: c.noise for c in config.conditions}
    return Backends(simulate or core_simulate(noise, config.world, config.task),
                    Spy(reality) if reality_spy else reality, trace)


def run(config: settings.ReplicateConfig, tmp_path: Path, name: str = 'out',
        **kw: Any) -> tuple[Store, Experiment]:
    """Run the whole replication into ``tmp_path / name``: its store and the experiment."""
    store = Store(tmp_path / name, config.hash)
    store.open(config.to_yaml())
    experiment = Experiment(config, kw.pop('backends', None) or backends(config), store, **kw)
    experiment.run()
    return store, experiment


def synthetic(trials: int = 10) -> report.Results:
    """Results whose step scores are MEANS with a little noise: known verdicts to report."""
    config = tiny(trials=trials)
    rng = np.random.default_rng(5)
    units = {}
    for c in config.conditions:
        for t in range(trials):
            for s in STEPS:
                value = MEANS[c.name][s - 1] + rng.normal(0, 0.01)
                units[c.key, t, s] = {'best_fitness': value, 'mean': value, 'world': 'x',
                                      'best_generation': GENERATIONS[c.name] + t % 3 - 1,
                                      'history': [[0, 0.5, 0.4, 4]]}
    return report.Results(config, units)
