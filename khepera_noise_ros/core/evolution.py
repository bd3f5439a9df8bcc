"""The appendix's steady-state tournament EA, as an ask/tell state machine.

A generation is ``population`` tournaments: two distinct members drawn at random, the
fitter (the first drawn on a tie) wins, and the loser is replaced by a mutant of the
winner (every gene plus U(-1, 1)).  ``ask()`` gives genomes and seeds, ``tell()`` takes
their fitness; many EAs can be evaluated as one batch without changing any result.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Iterator

import numpy as np
import numpy.typing as npt

from .network import GENES, check_genomes

FITNESS_MODES = ('stored', 'reevaluate')
BEST_MODES = ('ever', 'final', 'retest')


@dataclass(frozen=True)
class EAConfig:
    """The EA's settings; a bad value is a ValueError naming it.

    Args:
        population: members, >= 2.
        generations: generations of ``population`` tournaments each, >= 0.
        init_range: a random start draws genes from U(-init_range, init_range).
        mutation_range: a mutant's genes move by U(-mutation_range, mutation_range).
        fitness: 'stored' (each individual evaluated once, when born) or 'reevaluate'
            (both members afresh in every tournament).
        best: 'ever' (the highest single evaluation of the run), 'final' (the fittest
            of the last population) or 'retest' (the last population evaluated
            ``retest_episodes`` times each, the highest mean).
        retest_episodes: episodes per member for best='retest'.
    """

    population: int = 25
    generations: int = 50
    init_range: float = 0.4
    mutation_range: float = 1.0
    fitness: str = 'stored'
    best: str = 'ever'
    retest_episodes: int = 5

    def __post_init__(self) -> None:
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


@dataclass
class _Tournament:
    """One tournament, with every random draw it needs made in advance."""

    generation: int
    pair: tuple[int, int]
    noise: np.ndarray | None     # the mutation, added to the winner's genes
    seeds: np.ndarray            # episode seeds: the mutant's, or both members'
    state: str = 'waiting'       # waiting -> evaluating -> done
    results: dict[int, float] = field(default_factory=dict)   # member -> fitness told
    mutant: int | None = None    # the member replaced (the loser)
    genomes: dict[int, np.ndarray] | None = None   # members' genomes when it finished


# What ask() hands out: genomes, seeds, and who each evaluation is for.
_Batch = tuple[np.ndarray, np.ndarray, list[Any]]


def _pair(rng: np.random.Generator, population: int) -> tuple[int, int]:
    """Two distinct members drawn at random."""
    i, j = (int(m) for m in rng.choice(population, 2, replace=False))
    return i, j


class SteadyStateEA:
    """One run of the EA; drive it with ask()/tell() until ``done``.

    The result is exactly that of running the tournaments one after another,
    but ``ask()`` hands out every evaluation that no earlier, unfinished
    tournament can still change: tournaments on disjoint members run in the same
    batch.  (The random draws do not depend on fitness, so they are all made up
    front.)  A population of 25 needs about a fifth of the sequential rounds.
    """

    def __init__(self, config: EAConfig = PHASE1, seed: int = 0,
                 seed_genome: npt.ArrayLike | None = None):
        """Args:
            config: the EA's settings.
            seed: of every random draw of the run (members, pairs, mutations, seeds).
            seed_genome: (20,) genome the start population mutates; None: a random start.
        """
        self.config = cfg = config
        self.rng = rng = np.random.default_rng(seed)
        self.seed_genome = None if seed_genome is None else check_genomes(seed_genome)[0]
        if self.seed_genome is None:
            self.population = rng.uniform(-cfg.init_range, cfg.init_range,
                                          size=(cfg.population, GENES))
        else:
            self.population = self.seed_genome + rng.uniform(
                -cfg.mutation_range, cfg.mutation_range, size=(cfg.population, GENES))
        self.fitness = np.full(cfg.population, -np.inf)
        per = 2 if cfg.fitness == 'reevaluate' else 1
        self._initial_seeds = self._seeds(cfg.population)
        self._tournaments = [
            _Tournament(g, _pair(rng, cfg.population),
                        rng.uniform(-cfg.mutation_range, cfg.mutation_range, GENES),
                        self._seeds(per))
            for g in range(1, cfg.generations + 1) for _ in range(cfg.population)]
        self._retest_seeds = self._seeds(cfg.population * cfg.retest_episodes) \
            if cfg.best == 'retest' else None
        self.history: list[Generation] = []
        self.best_genome: np.ndarray | None = None
        self.best_fitness = -np.inf
        self.best_generation = 0
        self.evaluations = 0
        self.generation = 0
        self._committed = 0               # tournaments folded into the sequential record
        self._seq_fitness = self.fitness.copy()
        self._asked: _Batch | None = None   # (genomes, seeds, [(tournament or tag, member)])
        self._stage = 'initial'

    def _seeds(self, n: int) -> np.ndarray:
        return self.rng.integers(0, 2**53, size=n)

    @property
    def done(self) -> bool:
        """The run is over: nothing more to ask."""
        return self._stage == 'done'

    def ask(self) -> tuple[np.ndarray, np.ndarray]:
        """The evaluations the run waits for.

        Returns:
            (genomes (n, 20), episode seeds (n,)); n = 0 when done.
        """
        if self._asked is None:
            self._asked = self._next_batch()
        genomes, seeds, _ = self._asked
        return genomes.copy(), seeds.copy()

    def tell(self, fitness: npt.ArrayLike) -> None:
        """Take the fitness of what ``ask()`` gave.

        Args:
            fitness: (n,) finite values, in the order asked.

        Raises:
            ValueError: the wrong number of values, or one not finite.
            RuntimeError: the run is done.
        """
        if self.done:
            raise RuntimeError('the EA is done; nothing was asked')
        genomes, seeds, owners = self._asked if self._asked is not None else self._next_batch()
        fitness = np.asarray(fitness, dtype=np.float64).reshape(-1)
        if fitness.shape != (len(owners),) or not np.isfinite(fitness).all():
            raise ValueError(f'tell() needs {len(owners)} finite fitness values, '
                             f'got {fitness!r}')
        self._asked = None
        self.evaluations += fitness.size
        if self._stage == 'initial':
            self.fitness[:] = self._seq_fitness[:] = fitness
            self._note_best(self.population, fitness)
            self._record()
            self._stage = 'tournaments'
        elif self._stage == 'retest':
            self._choose_retested(fitness)
        else:
            for (t, member), f in zip(owners, fitness):
                t.results[member] = f
            for t in {id(t): t for t, _ in owners}.values():
                self._finish(t)
            self._commit()
        if self._stage == 'tournaments' and self._committed == len(self._tournaments):
            self._end_tournaments()

    # --- scheduling: which evaluations can run now ------------------------------------

    def _next_batch(self) -> _Batch:
        if self._stage == 'initial':
            owners: list[Any] = [('initial', m) for m in range(self.config.population)]
            return self.population.copy(), self._initial_seeds, owners
        if self._stage == 'retest':
            k = self.config.retest_episodes
            assert self._retest_seeds is not None           # drawn when best='retest'
            return np.repeat(self.population, k, axis=0), self._retest_seeds, [None] * len(
                self._retest_seeds)
        genomes: list[np.ndarray] = []
        seeds: list[int] = []
        owners = []
        blocked = {m for t in self._tournaments[self._committed:] if t.state == 'evaluating'
                   for m in self._reserved(t)}
        for t in self._tournaments[self._committed:]:
            if len(blocked) >= self.config.population:
                break
            if t.state != 'waiting':
                continue
            if blocked.intersection(t.pair):
                blocked.update(t.pair)    # later tournaments on these members must wait
                continue
            for member, genome, seed in self._start(t):
                genomes.append(genome)
                seeds.append(seed)
                owners.append((t, member))
            blocked.update(self._reserved(t))
        return np.array(genomes), np.array(seeds, dtype=np.int64), owners

    def _reserved(self, t: _Tournament) -> tuple[int | None, ...]:
        """Members a started tournament still holds: both while they are re-evaluated;
        only the loser while the mutant that replaced it awaits its fitness."""
        return t.pair if self.config.fitness == 'reevaluate' else (t.mutant,)

    def _start(self, t: _Tournament) -> Iterator[tuple[int, np.ndarray, int]]:
        """Begin a tournament whose members are settled; yield what it needs evaluated."""
        t.state, t.results = 'evaluating', {}
        i, j = t.pair
        if self.config.fitness == 'reevaluate':
            yield i, self.population[i].copy(), t.seeds[0]
            yield j, self.population[j].copy(), t.seeds[1]
            return
        loser = self._replace_loser(t, self.fitness[i], self.fitness[j])
        yield loser, self.population[loser].copy(), t.seeds[0]

    def _replace_loser(self, t: _Tournament, fi: float, fj: float) -> int:
        """Replace the loser by the winner's mutant; the loser."""
        i, j = t.pair
        winner, loser = (i, j) if fi >= fj else (j, i)
        assert t.noise is not None                      # freed only once committed
        self.population[loser] = self.population[winner] + t.noise
        self.fitness[loser] = -np.inf
        t.mutant = loser
        return loser

    def _finish(self, t: _Tournament) -> None:
        if self.config.fitness == 'reevaluate':
            i, j = t.pair
            self.fitness[i], self.fitness[j] = t.results[i], t.results[j]
            t.genomes = {m: self.population[m].copy() for m in t.pair}
            self._replace_loser(t, t.results[i], t.results[j])
        else:
            assert t.mutant is not None                     # set when it started
            self.fitness[t.mutant] = t.results[t.mutant]
            t.genomes = {t.mutant: self.population[t.mutant].copy()}
        t.state = 'done'

    # --- the sequential record: history and best, in tournament order -----------------

    def _commit(self) -> None:
        cfg = self.config
        while self._committed < len(self._tournaments) and \
                self._tournaments[self._committed].state == 'done':
            t = self._tournaments[self._committed]
            self.generation = t.generation
            members = list(t.results)
            assert t.genomes is not None and t.mutant is not None   # set when it finished
            self._note_best(np.array([t.genomes[m] for m in members]),
                            np.array([t.results[m] for m in members]))
            for m in members:
                self._seq_fitness[m] = t.results[m]
            if cfg.fitness == 'reevaluate':
                self._seq_fitness[t.mutant] = -np.inf
            self._committed += 1
            if self._committed % cfg.population == 0:
                self._record()
            t.noise = t.genomes = None    # free what the record no longer needs

    def _record(self) -> None:
        known = self._seq_fitness[np.isfinite(self._seq_fitness)]
        per = 2 if self.config.fitness == 'reevaluate' else 1
        evaluations = self.config.population + self._committed * per
        self.history.append(Generation(self.generation, float(known.max()),
                                       float(known.mean()), evaluations))

    def _note_best(self, genomes: np.ndarray, fitness: np.ndarray) -> None:
        if self.config.best != 'ever':
            return
        i = int(np.argmax(fitness))
        if fitness[i] > self.best_fitness:
            self.best_fitness = float(fitness[i])
            self.best_genome = genomes[i].copy()
            self.best_generation = self.generation

    def _end_tournaments(self) -> None:
        if self.config.best == 'final':
            i = int(np.argmax(self.fitness))
            self.best_genome, self.best_fitness = self.population[i].copy(), \
                float(self.fitness[i])
            self.best_generation = self.generation
        self._stage = 'retest' if self.config.best == 'retest' else 'done'

    def _choose_retested(self, scores: np.ndarray) -> None:
        means = scores.reshape(self.config.population, -1).mean(axis=1)
        i = int(np.argmax(means))
        self.best_genome, self.best_fitness = self.population[i].copy(), float(means[i])
        self.best_generation = self.generation
        self._stage = 'done'


def evolve(eas: list[SteadyStateEA], evaluate: Callable[[np.ndarray, np.ndarray], np.ndarray],
           progress: Callable[[list[SteadyStateEA]], object] | None = None) -> None:
    """Drive several EAs to the end, evaluating all their requests as one batch.

    Args:
        eas: the runs.
        evaluate: ``(genomes (n, 20), seeds (n,)) -> fitness (n,)``.
        progress: called with ``eas`` after each batch.
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
