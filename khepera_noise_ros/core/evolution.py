"""The appendix's steady-state tournament EA, as an ask/tell state machine.

A generation is ``population`` tournaments.  A tournament draws two distinct
members at random; the fitter one (the first drawn on a tie) wins, and the
loser is replaced by a mutant of the winner: every gene plus U(-1, 1).  A
random start draws genes from U(-0.4, 0.4); a seeded start mutates the seed.

Noisy fitness, ``fitness`` setting:
  'stored'      each individual is evaluated once, when it is born, and that
                value is used in every tournament it enters (the default);
  'reevaluate'  both members are evaluated afresh in every tournament.
The best individual, ``best`` setting:
  'ever'        the individual with the highest single evaluation seen in the
                run, and the generation it was seen in (the default);
  'final'       the fittest member of the last population by stored value;
  'retest'      the last population re-evaluated ``retest_episodes`` times
                each, the highest mean wins (guards against lucky episodes).

``ask()`` returns the genomes to evaluate next and one episode seed each;
``tell()`` takes their fitness.  Many EAs can be asked together and their
requests evaluated as one batch: results never depend on the batching.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .network import GENES, check_genomes

FITNESS_MODES = ('stored', 'reevaluate')
BEST_MODES = ('ever', 'final', 'retest')


@dataclass(frozen=True)
class EAConfig:
    population: int = 25
    generations: int = 50
    init_range: float = 0.4
    mutation_range: float = 1.0
    fitness: str = 'stored'
    best: str = 'ever'
    retest_episodes: int = 5

    def __post_init__(self):
        if not isinstance(self.population, (int, np.integer)) or self.population < 2:
            raise ValueError(f'population must be an integer >= 2, got {self.population!r}')
        if not isinstance(self.generations, (int, np.integer)) or self.generations < 0:
            raise ValueError(f'generations must be an integer >= 0, got {self.generations!r}')
        for name in ('init_range', 'mutation_range'):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0:
                raise ValueError(f'{name} must be a finite number >= 0, got {v!r}')
        if self.fitness not in FITNESS_MODES:
            raise ValueError(f'fitness must be one of {FITNESS_MODES}, got {self.fitness!r}')
        if self.best not in BEST_MODES:
            raise ValueError(f'best must be one of {BEST_MODES}, got {self.best!r}')
        if self.retest_episodes < 1:
            raise ValueError(f'retest_episodes must be >= 1, got {self.retest_episodes!r}')


PHASE1 = EAConfig(population=25, generations=50)
PHASE2 = EAConfig(population=10, generations=5)


@dataclass
class Generation:
    """Statistics of the population at the end of a generation (0 = initial)."""

    generation: int
    best: float
    mean: float
    evaluations: int


class SteadyStateEA:
    """One run of the EA; drive it with ask()/tell() until ``done``."""

    def __init__(self, config: EAConfig = PHASE1, seed: int = 0, seed_genome=None):
        self.config = config
        self.rng = np.random.default_rng(seed)
        self.seed_genome = None if seed_genome is None else check_genomes(seed_genome)[0]
        self.history: list[Generation] = []
        self.best_genome: np.ndarray | None = None
        self.best_fitness = -np.inf
        self.best_generation = 0
        self.evaluations = 0
        self.generation = 0
        self._pending: np.ndarray | None = None
        self._result: np.ndarray | None = None
        self._steps = self._run()
        self._pending = next(self._steps)

    @property
    def done(self) -> bool:
        return self._pending is None

    def ask(self) -> tuple[np.ndarray, np.ndarray]:
        """(genomes (n, 20), episode seeds (n,)) awaiting evaluation; n = 0 when done."""
        if self._pending is None:
            return np.empty((0, GENES)), np.empty(0, np.int64)
        if self._seeds is None:
            self._seeds = self.rng.integers(0, 2**53, size=len(self._pending))
        return self._pending.copy(), self._seeds.copy()

    def tell(self, fitness) -> None:
        if self._pending is None:
            raise RuntimeError('the EA is done; nothing was asked')
        fitness = np.asarray(fitness, dtype=np.float64).reshape(-1)
        if fitness.shape != (len(self._pending),) or not np.isfinite(fitness).all():
            raise ValueError(f'tell() needs {len(self._pending)} finite fitness values, '
                             f'got {fitness!r}')
        if self._seeds is None:
            self.ask()
        self.evaluations += fitness.size
        self._note_best(self._pending, fitness)
        try:
            self._pending = self._steps.send(fitness)
        except StopIteration:
            self._pending = None

    _seeds: np.ndarray | None = None

    def _evaluate(self, genomes: np.ndarray):
        self._seeds = None
        return (yield genomes)

    def _note_best(self, genomes: np.ndarray, fitness: np.ndarray) -> None:
        if self.config.best != 'ever':
            return
        i = int(np.argmax(fitness))
        if fitness[i] > self.best_fitness:
            self.best_fitness = float(fitness[i])
            self.best_genome = genomes[i].copy()
            self.best_generation = self.generation

    def _mutant(self, parent: np.ndarray, spread: float) -> np.ndarray:
        return parent + self.rng.uniform(-spread, spread, size=GENES)

    def _run(self):
        cfg, rng = self.config, self.rng
        if self.seed_genome is None:
            pop = rng.uniform(-cfg.init_range, cfg.init_range, size=(cfg.population, GENES))
        else:
            pop = np.stack([self._mutant(self.seed_genome, cfg.mutation_range)
                            for _ in range(cfg.population)])
        fit = np.array((yield from self._evaluate(pop)))
        self._record(fit)
        for self.generation in range(1, cfg.generations + 1):
            for _ in range(cfg.population):
                i, j = rng.choice(cfg.population, size=2, replace=False)
                if cfg.fitness == 'reevaluate':
                    fit[[i, j]] = yield from self._evaluate(pop[[i, j]])
                winner, loser = (i, j) if fit[i] >= fit[j] else (j, i)
                pop[loser] = self._mutant(pop[winner], cfg.mutation_range)
                fit[loser] = -np.inf
                if cfg.fitness == 'stored':
                    fit[loser] = (yield from self._evaluate(pop[loser][None]))[0]
            self._record(fit)
        if cfg.best == 'final':
            i = int(np.argmax(fit))
            self.best_genome, self.best_fitness = pop[i].copy(), float(fit[i])
            self.best_generation = self.generation
        elif cfg.best == 'retest':
            k = cfg.retest_episodes
            scores = np.asarray((yield from self._evaluate(np.repeat(pop, k, axis=0))))
            means = scores.reshape(cfg.population, k).mean(axis=1)
            i = int(np.argmax(means))
            self.best_genome, self.best_fitness = pop[i].copy(), float(means[i])
            self.best_generation = self.generation
        self.population, self.fitness = pop, fit

    def _record(self, fit: np.ndarray) -> None:
        known = fit[np.isfinite(fit)]
        self.history.append(Generation(self.generation, float(known.max()),
                                       float(known.mean()), self.evaluations))


def evolve(eas: list[SteadyStateEA], evaluate, progress=None) -> None:
    """Drive several EAs to the end, evaluating all their requests as one batch.

    ``evaluate(genomes (n, 20), seeds (n,)) -> fitness (n,)``.  ``progress(eas)``
    is called after each batch.
    """
    while True:
        active = [ea for ea in eas if not ea.done]
        if not active:
            return
        asks = [ea.ask() for ea in active]
        fitness = evaluate(np.concatenate([a[0] for a in asks]),
                           np.concatenate([a[1] for a in asks]))
        edges = np.cumsum([0] + [len(a[0]) for a in asks])
        for ea, lo, hi in zip(active, edges[:-1], edges[1:]):
            ea.tell(fitness[lo:hi])
        if progress is not None:
            progress(eas)
