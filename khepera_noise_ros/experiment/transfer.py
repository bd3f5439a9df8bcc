"""The transfer experiment, measured: which simulator's controllers work on the robot?

Arms (``arms``): controllers evolved in the stock simulator (as configured), in it under
each of the paper's two noise models at 5% (``independent``, ``combination``), in the
diagnosed simulator (the fitted effects), and, where the robot is affordable to train on,
on the robot itself with the same EA budget (``robot_trained``, the ceiling: each
trial's population seeded from that trial's stock best, as the replication's phase 2 and
``benchmark/foreign/learnability.py`` do).  Every run chooses its best by re-test (its
last population run ``retest_episodes`` more episodes each, as ``replicate`` does), and
every best is tested on the robot on ``test_episodes`` episodes: trial i of every arm on
the same episodes, and on those episodes again in the simulator it was evolved in.
An arm whose simulator is another arm's (the stock simulator is the paper's combination
model unless configured otherwise) shares that arm's controllers.

Reality is any callable ``(genomes (n, 20), seeds (n,)) -> fitness (n,)``.  When it fails
(a robot stops answering) or the run is interrupted, ``Stopped`` carries what was
measured so far.  ``transfer_stats.block`` turns an ``Outcome`` into the ``transfer``
block of diagnosis.json.
"""
from __future__ import annotations

import dataclasses
import zlib
from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np

from ..core import evolution
from ..core.noise import NoiseModel
from ..core.evaluation import episode_fitness
from ..effects.simulate import EffectEpisodes
from ..simconfig import SimConfig
from .protocol import episodes_per_run

Reality = Callable[[np.ndarray, np.ndarray], np.ndarray]

STOCK, DIAGNOSED, ROBOT = 'stock', 'diagnosed', 'robot_trained'
TRIALS = 10
TEST_EPISODES = 10
EA = dataclasses.replace(evolution.PHASE1, best='retest', retest_episodes=5)
_PURPOSE = {'evolve': 1, 'test': 2}


class Progress(Protocol):
    """Where a long run is: ``start`` with the episodes to run, then stages and episodes."""

    def start(self, total: int) -> None: ...

    def stage(self, text: str) -> None: ...

    def advance(self, episodes: int) -> None: ...


class _Quiet:
    def start(self, total: int) -> None:
        pass

    def stage(self, text: str) -> None:
        pass

    def advance(self, episodes: int) -> None:
        pass


@dataclass
class SimEvaluator:
    """(genomes, seeds) -> fitness in the simulator of ``config``: one episode per genome."""

    config: SimConfig

    def __call__(self, genomes, seeds) -> np.ndarray:
        c = self.config
        return episode_fitness(EffectEpisodes(c.world, c.noise, c.task, tuple(c.effects)),
                               genomes, seeds)


def paper_models() -> dict[str, NoiseModel]:
    """The paper's two noise models at its first level (5%), from the replication's
    settings: {'combination': 3% + 2%, 'independent': 5%}."""
    from .config import load
    return {c.model: c.noise for c in load().levels[0].conditions}


def arms(stock: SimConfig, diagnosed: SimConfig | None) -> dict[str, SimConfig]:
    """The simulators evolved in, by arm: the stock one, the diagnosed one, and the stock
    one with its noise replaced by each of the paper's models."""
    out = {STOCK: stock}
    if diagnosed is not None:
        out[DIAGNOSED] = diagnosed
    for model, noise in paper_models().items():
        out[model] = dataclasses.replace(stock, noise=noise)
    return out


@dataclass
class Outcome:
    """Everything measured, per arm: (trials,) means over the test episodes."""

    arms: list[str]                      # in the order of the report: simulators, then robot
    trials: int
    test_episodes: int
    ea: evolution.EAConfig
    seed: int
    same_as: dict[str, str] = field(default_factory=dict)   # arm -> the arm it shares
    bests: dict[str, np.ndarray] = field(default_factory=dict)
    sim: dict[str, np.ndarray] = field(default_factory=dict)
    real: dict[str, np.ndarray] = field(default_factory=dict)
    stage: str = ''                      # what was running when it stopped
    error: str | None = None

    @property
    def complete(self) -> bool:
        return self.error is None and all(a in self.real for a in self.arms)

    def done(self) -> str:
        """'evolved: stock, diagnosed; tested on the robot: stock'."""
        evolved = [a for a in self.arms if a in self.bests]
        tested = [a for a in self.arms if a in self.real]
        return (f"evolved: {', '.join(evolved) or 'none'}; tested on the robot: "
                f"{', '.join(tested) or 'none'}")


class Stopped(RuntimeError):
    """Reality failed or the run was interrupted; ``outcome`` holds what was measured."""

    def __init__(self, message: str, outcome: Outcome):
        super().__init__(message)
        self.outcome = outcome


def seeds_for(seed: int, arm: str, purpose: str) -> np.random.SeedSequence:
    """An arm's own seeds: the same whichever other arms run, or whether it was cached."""
    return np.random.SeedSequence([seed, zlib.crc32(arm.encode()), _PURPOSE[purpose]])


def episode_seeds(seed: int, trials: int, test_episodes: int) -> np.ndarray:
    """(trials, test_episodes) test episodes: trial i of every arm runs row i."""
    words = np.random.SeedSequence([seed, _PURPOSE['test']]).generate_state(
        trials * test_episodes, np.uint64) >> np.uint64(11)
    return words.astype(np.int64).reshape(trials, test_episodes)


def evolve(evaluate: Reality, seeds: np.random.SeedSequence, trials: int,
           ea: evolution.EAConfig = EA, start: np.ndarray | None = None) -> np.ndarray:
    """(trials, 20) bests of ``trials`` runs as one batch; run i seeded from ``start[i]``."""
    starts = [None] * trials if start is None else list(start)
    eas = [evolution.SteadyStateEA(ea, int(s), seed_genome=g)
           for s, g in zip(seeds.generate_state(trials), starts)]
    evolution.evolve(eas, evaluate)
    return np.stack([e.best_genome for e in eas])


def run(simulators: dict[str, SimConfig], reality: Reality, trials: int = TRIALS,
        ea: evolution.EAConfig = EA, test_episodes: int = TEST_EPISODES, seed: int = 0,
        ceiling: bool = False, progress: Progress | None = None,
        evolved: dict[str, np.ndarray] | None = None) -> Outcome:
    """Evolve every arm, then test each best on the robot and in its simulator.

    Args:
        simulators: arm -> the simulator it evolves in; must hold ``stock``.
        reality: the robot.
        trials: EA runs per arm (>= 2); ea: their budget and choice of the best.
        test_episodes: episodes of each best's test (>= 1).
        seed: of every run and test episode.
        ceiling: also train on the robot with ``ea`` (the ``robot_trained`` arm).
        progress: told the episodes to run and as they run.
        evolved: arm -> (trials, 20) bests already evolved with these settings and seed
            (the benchmark shares the stock simulator's across robots).

    Raises:
        ValueError: bad settings, named.
        Stopped: reality raised or the run was interrupted; what was measured is in it.
    """
    if STOCK not in simulators:
        raise ValueError(f'the transfer experiment needs a {STOCK!r} arm, got '
                         f'{sorted(simulators)}')
    if isinstance(trials, bool) or not isinstance(trials, int) or trials < 2:
        raise ValueError(f'the transfer experiment needs at least 2 trials per arm, '
                         f'got {trials!r}')
    if isinstance(test_episodes, bool) or not isinstance(test_episodes, int) \
            or test_episodes < 1:
        raise ValueError(f'test episodes must be an integer >= 1, got {test_episodes!r}')
    names = list(simulators) + ([ROBOT] if ceiling else [])
    out = Outcome(names, trials, test_episodes, ea, seed)
    for i, name in enumerate(simulators):
        same = next((n for n in list(simulators)[:i] if simulators[n] == simulators[name]),
                    None)
        if same is not None:
            out.same_as[name] = same
    progress = progress or _Quiet()
    progress.start(_total(out, ea, evolved or {}))
    test = episode_seeds(seed, trials, test_episodes)
    try:
        _evolve_arms(out, simulators, evolved or {}, progress)
        for name in _test_order(out):
            _test(out, name, simulators.get(name), reality, test, progress)
        if ceiling:
            out.stage = 'training the robot_trained arm on the robot'
            progress.stage(out.stage)
            out.bests[ROBOT] = evolve(_counted(_guarded(reality), progress),
                                      seeds_for(seed, ROBOT, 'evolve'), trials, ea,
                                      start=out.bests[STOCK])
            _test(out, ROBOT, None, reality, test, progress)
    except (_RealityFailed, KeyboardInterrupt) as exc:
        out.error = str(exc) or 'interrupted'
        raise Stopped(out.error, out) from exc
    out.stage = ''
    return out


def _test_order(out: Outcome) -> list[str]:
    """Stock and diagnosed first (the recommendation needs them), then the others."""
    first = [a for a in (STOCK, DIAGNOSED) if a in out.arms and a != ROBOT]
    return first + [a for a in out.arms if a not in first and a != ROBOT]


def _evolve_arms(out: Outcome, simulators: dict[str, SimConfig],
                 evolved: dict[str, np.ndarray], progress: Progress) -> None:
    for name, config in simulators.items():
        if name in out.same_as:
            out.bests[name] = out.bests[out.same_as[name]]
        elif name in evolved:
            out.bests[name] = np.asarray(evolved[name], np.float64)
        else:
            out.stage = f'evolving in the {name} simulator'
            progress.stage(out.stage)
            out.bests[name] = evolve(_counted(SimEvaluator(config), progress),
                                     seeds_for(out.seed, name, 'evolve'), out.trials, out.ea)


def _test(out: Outcome, name: str, config: SimConfig | None, reality: Reality,
          test: np.ndarray, progress: Progress) -> None:
    """Arm ``name``'s bests on the robot and (with a simulator) in it, trial i on row i."""
    if name in out.same_as:
        out.sim[name] = out.sim[out.same_as[name]]
        out.real[name] = out.real[out.same_as[name]]
        return
    genomes = np.repeat(out.bests[name], out.test_episodes, axis=0)
    flat = test.reshape(-1)
    shape = (out.trials, out.test_episodes)
    if config is not None:
        out.sim[name] = _counted(SimEvaluator(config), progress)(genomes, flat) \
            .reshape(shape).mean(axis=1)
    out.stage = f'testing the {name} controllers on the robot'
    progress.stage(out.stage)
    real = _counted(_guarded(reality), progress)(genomes, flat)
    out.real[name] = np.asarray(real, np.float64).reshape(shape).mean(axis=1)


class _RealityFailed(RuntimeError):
    pass


def _guarded(reality: Reality) -> Reality:
    """Reality whose failure (any exception: a port gone, a robot that stops answering)
    ends the run with what was measured."""
    def evaluate(genomes, seeds):
        try:
            values = np.asarray(reality(genomes, seeds), np.float64)
        except Exception as exc:            # noqa: BLE001  (whatever the robot raised)
            raise _RealityFailed(' '.join(str(exc).split()) or type(exc).__name__) from exc
        if values.shape != (len(seeds),) or not np.isfinite(values).all():
            raise _RealityFailed(f'reality returned {values.shape} values for {len(seeds)} '
                                 f'episodes, or values that are not finite')
        return values
    return evaluate


def _counted(evaluate: Reality, progress: Progress) -> Reality:
    def run(genomes, seeds):
        values = evaluate(genomes, seeds)
        progress.advance(len(seeds))
        return values
    return run


def _total(out: Outcome, ea: evolution.EAConfig, evolved: dict) -> int:
    """Episodes the run will play: evolutions, then each arm's tests (robot and simulator)."""
    per_run = episodes_per_run(ea) * out.trials
    test = out.trials * out.test_episodes
    own = [a for a in out.arms if a not in out.same_as]
    runs = sum(1 for a in own if a not in evolved)
    return runs * per_run + sum(test * (1 if a == ROBOT else 2) for a in own)
