"""The procedure of section 4.4, steps 1-5, for every condition and trial at once.

1. evolve in simulation from a random population (phase 1)
2. test phase 1's best in simulation
3. test phase 1's best in reality
4. evolve in reality from a population seeded with phase 1's best (phase 2)
5. test phase 2's best in reality

and, with the ceiling arm (``config.ceiling``), from the same phase-1 best:

6. evolve in reality with the ceiling's budget (the full budget by default)
7. test its best in reality, on the test episodes of steps 2, 3 and 5

Every (condition, trial) runs the same step together, so each round of the
EAs is one batch: one batch per condition in simulation, where each condition
has its own noise model, and one batch for all conditions in reality.  Every
EA and every test has its own seed, derived from the run's seed, the
condition and the trial, and evaluators draw each episode's randomness from
the episode's seed: a trial gives the same result whatever else is in its
batch, and however the run is interrupted and resumed.
"""
from __future__ import annotations

import functools
import time
import zlib
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..core import network, task
from ..core.evolution import EAConfig, SteadyStateEA
from ..core.khepera import World
from ..core.noise import NoiseModel
from .config import Condition, ReplicateConfig
from .store import Store

Evaluator = Callable[[np.ndarray, np.ndarray], np.ndarray]
Request = tuple[np.ndarray, np.ndarray]           # (genomes (n, 20), seeds (n,))
# Simulation of several conditions at once: condition key -> request -> fitness.
Simulate = Callable[[dict[str, Request]], dict[str, np.ndarray]]

STEPS = {1: 'evolve in simulation', 2: 'test in simulation', 3: 'test in reality',
         4: 'evolve in reality', 5: 'test in reality'}
CEILING_STEPS = {6: 'evolve in reality, ceiling budget', 7: 'test in reality, after the ceiling'}
_PURPOSE = {'phase1': 1, 'phase2': 4, 'test': 2, 'ceiling': 6}
CHECKPOINT_S = 5.0


@dataclass
class Backends:
    """Where episodes run: simulation per condition, and the one reality."""

    simulate: Simulate
    reality: Evaluator
    # reality episodes with their per-step record: the real tests use it when there is
    # one, so Figure 8 can show the very test that ranked a controller best
    reality_trace: Callable[[np.ndarray, np.ndarray], task.Trace] | None = None
    description: dict = field(default_factory=dict)
    # a first guess of each world's cost, for the time left before it is measured
    seconds_per_episode: dict = field(default_factory=dict)


def seed_for(base: int, condition: str, trial: int, purpose: str, count: int | None = None):
    """A seed (< 2**53, exact in a message) for one purpose of one trial; ``count`` gives many."""
    entropy = [base, zlib.crc32(condition.encode()), trial, _PURPOSE[purpose]]
    words = np.random.SeedSequence(entropy).generate_state(count or 1, np.uint64) >> np.uint64(11)
    return words.astype(np.int64) if count else int(words[0])


def per_condition(evaluators: dict[str, Evaluator]) -> Simulate:
    """Simulate with one evaluator per condition, one batch after the other."""
    return lambda requests: {key: np.asarray(evaluators[key](*request), np.float64)
                             for key, request in requests.items()}


class _SplitNoise:
    """Each condition's noise model on its own columns of one batch of readings."""

    def __init__(self, parts: list[tuple[slice, NoiseModel]]):
        self.parts = parts
        # the episode draws one dependent-noise channel per group of the widest model
        self.groups = max((model.groups for _, model in parts), key=len)

    def apply(self, base, sensor_draws, group_draws, out=None):
        out = np.empty_like(base) if out is None else out
        for cols, model in self.parts:
            out[:, cols] = model.apply(base[:, cols], sensor_draws[:, cols], group_draws[:, cols])
        return out


class ConditionEpisodes(task.Episodes):
    """The core's episodes with each robot under its own condition's noise model.

    ``lay_out`` says which robots of the next batch belong to which condition;
    a robot node over this backend then simulates every condition in one batch.
    """

    def __init__(self, noise: dict[str, NoiseModel], world: World, episode: task.Task):
        super().__init__(world, NoiseModel(), episode)
        self.models = noise

    def lay_out(self, sizes: dict[str, int]) -> None:
        edges = np.cumsum([0] + list(sizes.values()))
        self.noise = _SplitNoise([(slice(lo, hi), self.models[k])
                                  for k, lo, hi in zip(sizes, edges[:-1], edges[1:])])


def batch_simulate(evaluate: Evaluator, episodes: ConditionEpisodes) -> Simulate:
    """All conditions as one batch of ``evaluate`` (the graph) over ``episodes``."""
    def simulate(requests: dict[str, Request]) -> dict[str, np.ndarray]:
        keys = list(requests)
        episodes.lay_out({k: len(requests[k][1]) for k in keys})
        fitness = np.asarray(evaluate(np.concatenate([requests[k][0] for k in keys]),
                                      np.concatenate([requests[k][1] for k in keys])))
        edges = np.cumsum([0] + [len(requests[k][1]) for k in keys])
        return {k: fitness[lo:hi] for k, lo, hi in zip(keys, edges[:-1], edges[1:])}
    return simulate


def core_simulate(noise: dict[str, NoiseModel], world: World, episode: task.Task) -> Simulate:
    """All conditions in one in-process batch: the graph's numbers without the graph."""
    episodes = ConditionEpisodes(noise, world, episode)
    return batch_simulate(lambda genomes, seeds: play(episodes, genomes, seeds)[0], episodes)


def chunked(evaluate: Evaluator, capacity: int) -> Evaluator:
    """Evaluate a batch larger than the robots there are, ``capacity`` episodes at a time."""
    def run(genomes, seeds) -> np.ndarray:
        return np.concatenate([np.asarray(evaluate(genomes[i:i + capacity],
                                                   seeds[i:i + capacity]), np.float64)
                               for i in range(0, len(seeds), capacity)])
    return run


def chunked_trace(trace: Callable[[np.ndarray, np.ndarray], task.Trace],
                  capacity: int) -> Callable[[np.ndarray, np.ndarray], task.Trace]:
    """``chunked`` for traces: the chunks' records side by side, robots on axis 1."""
    def run(genomes, seeds) -> task.Trace:
        parts = [trace(genomes[i:i + capacity], seeds[i:i + capacity])
                 for i in range(0, len(seeds), capacity)]
        return task.Trace(*(np.concatenate([getattr(p, f) for p in parts], axis=1)
                            for f in ('bearing_deg', 'readings', 'direction', 'power')))
    return run


def episode_fitness(trace: task.Trace) -> np.ndarray:
    """Each episode's fitness from its trace, summed step by step in float32 like the
    evaluators, so a traced test scores exactly what an untraced one would."""
    total = np.add.accumulate(trace.fitness.astype(np.float32), axis=0)[-1]
    return (total / np.float32(len(trace.fitness))).astype(np.float64)


def play(backend, genomes, seeds) -> tuple[np.ndarray, task.Trace]:
    """Episodes on any backend with the Episodes interface (the emulated world, in process).

    Returns fitness (B,), summed in float32 step by step as ``core.task.run``
    and the graph do, and the per-step trace.
    """
    weights = network.unpack(genomes)
    readings = backend.reset(np.asarray(seeds, np.int64), robots=len(seeds))
    total = np.zeros(len(seeds), np.float32)
    rows = []
    while readings is not None:
        readings = np.asarray(readings, np.float32)
        direction, power = network.act(weights, readings)
        total += task.step_fitness(readings, power)
        bearing = backend.bearing_deg
        rows.append((np.full(len(seeds), np.nan) if bearing is None else bearing,
                     readings.copy(), direction, power))
        readings = backend.step(direction, power)
    trace = task.Trace(*(np.stack(col) for col in zip(*rows)))
    return (total / len(rows)).astype(np.float64), trace


Unit = tuple[Condition, int]          # (condition, trial index from 0)


class Experiment:
    """Runs what the store does not hold yet; ``progress`` shows where it is."""

    def __init__(self, config: ReplicateConfig, backends: Backends, store: Store,
                 progress=None, checkpoint_s: float = CHECKPOINT_S):
        self.config = config
        self.backends = backends
        self.store = store
        self.progress = progress
        self.checkpoint_s = checkpoint_s
        self.units: list[Unit] = [(c, t) for c in config.conditions for t in range(config.trials)]
        self.steps = {**STEPS, **(CEILING_STEPS if config.ceiling is not None else {})}

    def episodes_left(self) -> dict[str, int]:
        """Episodes still to run in simulation and in reality (for the progress bar)."""
        left = {'simulation': 0, 'reality': 0}
        for step in self.steps:
            left[_world(step)] += sum(self._cost(step) - self._done_in(step, unit)
                                      for unit in self.units)
        return left

    def run(self) -> None:
        self.evolve(1)
        self.test(2)
        self.test(3)
        self.evolve(4)
        self.test(5)
        if self.config.ceiling is not None:
            self.evolve(6)
            self.test(7)

    # --- steps -------------------------------------------------------------------------

    def evolve(self, step: int) -> None:
        """Step 1, 4 or 6 for every unit not finished yet, all in one batch per round."""
        todo = [u for u in self.units if self._load(u, step) is None]
        if not todo:
            return
        eas, told = {}, {}
        for unit in todo:
            eas[unit], told[unit] = self._restore(step, unit)
        self._stage(step, todo)
        last = time.monotonic()
        try:
            while active := {u: ea for u, ea in eas.items() if not ea.done}:
                asks = {u: ea.ask() for u, ea in active.items()}
                fitness, _ = self._evaluate(step, asks)
                for unit, ea in active.items():
                    ea.tell(fitness[unit])
                    told[unit].extend(fitness[unit].tolist())
                self._advance(sum(len(a[1]) for a in asks.values()),
                              min(ea.generation for ea in active.values()))
                if time.monotonic() - last > self.checkpoint_s:
                    self._checkpoint(step, eas, told)
                    last = time.monotonic()
        except BaseException:
            self._checkpoint(step, eas, told)
            raise
        for unit, ea in eas.items():
            self._save(unit, step, evolution_result(ea, step))

    def test(self, step: int) -> None:
        """Step 2, 3, 5 or 7: a best genome, on the test episodes of its trial."""
        todo = [u for u in self.units if self._load(u, step) is None]
        if not todo:
            return
        self._stage(step, todo)
        n = self.config.test_episodes
        asks = {u: (np.repeat(np.asarray([self._genome(u, step)]), n, axis=0),
                    self._seed(u, 'test', n)) for u in todo}
        traced = step >= 3 and self.backends.reality_trace is not None
        fitness, per_step = self._evaluate(step, asks, traced)
        self._advance(n * len(todo), None)
        for unit in todo:
            genome, seeds = asks[unit]
            result = {'kind': 'test', 'world': _world(step), 'genome': genome[0].tolist(),
                      'seeds': seeds.tolist(), 'fitness': fitness[unit].tolist(),
                      'mean': float(np.mean(fitness[unit]))}
            if traced:
                result['step_fitness'] = per_step[unit].T.tolist()    # episode, then step
            self._save(unit, step, result)

    # --- helpers -----------------------------------------------------------------------

    def _restore(self, step: int, unit: Unit) -> tuple[SteadyStateEA, list[float]]:
        condition, trial = unit
        if step == 1:
            ea = SteadyStateEA(self.config.phase1, seed=self._seed(unit, 'phase1'))
        else:
            config, purpose = (self.config.phase2, 'phase2') if step == 4 else \
                (self.config.ceiling, 'ceiling')
            ea = SteadyStateEA(config, seed=self._seed(unit, purpose),
                               seed_genome=self._genome(unit, step))
        told = self.store.load_checkpoint(condition.key, trial, step)
        replay(ea, told)
        return ea, told

    def _checkpoint(self, step: int, eas: dict, told: dict) -> None:
        for (condition, trial), ea in eas.items():
            if not ea.done and told[condition, trial]:
                self.store.save_checkpoint(condition.key, trial, step, told[condition, trial])

    def _evaluate(self, step: int, asks: dict[Unit, Request], traced: bool = False):
        """One batch per condition in simulation (steps 1-2), one for all in reality.

        Returns fitness by unit and, with ``traced``, each unit's per-step fitness
        (steps, episodes); without, that is empty.
        """
        group = (lambda u: u[0].key) if step <= 2 else (lambda u: 'reality')
        requests: dict[str, list[Unit]] = {}
        for unit in asks:
            requests.setdefault(group(unit), []).append(unit)
        batches = {g: (np.concatenate([asks[u][0] for u in us]),
                       np.concatenate([asks[u][1] for u in us])) for g, us in requests.items()}
        per_step = None
        if step <= 2:
            results = self.backends.simulate(batches)
        elif traced:
            trace = self.backends.reality_trace(*batches['reality'])
            per_step = trace.fitness
            results = {'reality': episode_fitness(trace)}
        else:
            results = {'reality': self.backends.reality(*batches['reality'])}
        fitness, steps = {}, {}
        for g, us in requests.items():
            values = np.asarray(results[g], np.float64)
            edges = np.cumsum([0] + [len(asks[u][1]) for u in us])
            if values.shape != (edges[-1],) or not np.isfinite(values).all():
                raise RuntimeError(f'the {g} evaluator returned {values.shape} values for '
                                   f'{edges[-1]} episodes, or values that are not finite')
            for u, lo, hi in zip(us, edges[:-1], edges[1:]):
                fitness[u] = values[lo:hi]
                if per_step is not None:
                    steps[u] = per_step[:, lo:hi]
        return fitness, steps

    def _genome(self, unit: Unit, step: int) -> list[float]:
        """The genome a step starts from: phase 1's best for steps 2-4 and 6, phase 2's for
        5, the ceiling arm's for 7."""
        source = self._load(unit, {5: 4, 7: 6}.get(step, 1))
        return source['best_genome']

    def _seed(self, unit: Unit, purpose: str, count: int | None = None):
        return seed_for(self.config.seed, unit[0].key, unit[1], purpose, count)

    def _load(self, unit: Unit, step):
        return self.store.load(unit[0].key, unit[1], step)

    def _save(self, unit: Unit, step: int, result: dict) -> None:
        self.store.save(unit[0].key, unit[1], step, result)

    def _cost(self, step: int) -> int:
        """Episodes one unit of a step takes."""
        phase = {1: self.config.phase1, 4: self.config.phase2, 6: self.config.ceiling}.get(step)
        return self.config.test_episodes if phase is None else episodes_per_run(phase)

    def _done_in(self, step: int, unit: Unit) -> int:
        if self._load(unit, step) is not None:
            return self._cost(step)
        if step in (1, 4, 6):
            return len(self.store.load_checkpoint(unit[0].key, unit[1], step))
        return 0

    def _stage(self, step: int, todo: list[Unit]) -> None:
        if self.progress is not None:
            generations = {1: self.config.phase1, 4: self.config.phase2,
                           6: self.config.ceiling}.get(step)
            self.progress.stage(step, self.steps[step], _world(step), todo,
                                generations and generations.generations, len(self.steps))

    def _advance(self, episodes: int, generation: int | None) -> None:
        if self.progress is not None:
            self.progress.advance(episodes, generation)


def replay(ea: SteadyStateEA, told: list[float]) -> None:
    """Bring a fresh EA to where it was by telling it the logged fitness values again."""
    used = 0
    while used < len(told):
        size = len(ea.ask()[1])
        if size == 0 or used + size > len(told):
            raise ValueError(f'checkpoint does not fit this EA: {len(told)} values logged, '
                             f'the EA asked for {used + size}')
        ea.tell(told[used:used + size])
        used += size


def evolution_result(ea: SteadyStateEA, step: int) -> dict:
    return {'kind': 'evolve', 'world': _world(step),
            'seed_genome': None if ea.seed_genome is None else ea.seed_genome.tolist(),
            'best_genome': ea.best_genome.tolist(), 'best_fitness': ea.best_fitness,
            'best_generation': best_generation(ea), 'evaluations': ea.evaluations,
            'history': [[g.generation, g.best, g.mean, g.evaluations] for g in ea.history]}


def best_generation(ea: SteadyStateEA) -> int:
    """The generation at which the run reached its best fitness (the paper's 35.0 against
    42.8).  A re-tested or final best is chosen at the end, so for those it is the first
    generation whose population held the highest fitness of the run."""
    if ea.config.best == 'ever' or not ea.history:
        return ea.best_generation
    best = [g.best for g in ea.history]
    return ea.history[int(np.argmax(best))].generation


@functools.lru_cache(maxsize=8)
def episodes_per_run(config: EAConfig) -> int:
    """Episodes one EA run evaluates, found by running it on constant fitness."""
    ea = SteadyStateEA(config, seed=0)
    while not ea.done:
        ea.tell(np.zeros(len(ea.ask()[1])))
    return ea.evaluations


def _world(step: int) -> str:
    return 'simulation' if step <= 2 else 'reality'
