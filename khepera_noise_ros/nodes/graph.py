"""``GraphEvaluator``: genomes scored through worker pairs of nodes, the topic counterpart of
``core.evaluation.CoreEvaluator`` (the same seeds give the same numbers)."""
from __future__ import annotations

import time
from typing import Callable, Sequence

import numpy as np
from rclpy.executors import Executor
from rclpy.node import Node
from rclpy.parameter import parameter_value_to_python

from ..core.network import GENES, check_genomes
from ..core.task import Trace
from . import protocol, schedule
from .discovery import discover, is_pattern
from .dropped import Dropped
from .episode import Chunk, Episode, EpisodeFailed, EpisodeIds, episode_fitness
from .protocol import BEARING, CMD_TURN, LIGHT
from .wake import Wake
from .workers import DONE, TOO_LARGE, Worker, WorkerState

__all__ = ['GraphEvaluator', 'EpisodeFailed', 'EpisodeIds', 'episode_fitness']


class GraphEvaluator:
    """``(genomes (n, 20), seeds (n,)) -> fitness (n,)`` through one or more worker pairs.

    Args:
        node: the node whose publishers, subscriptions and clients talk to the workers.
        robot_namespace: the one worker's namespace, when ``workers`` is empty.
        controller_node, robot_node: that worker's node names (default: found in the
            graph).
        stall_timeout_s: how long an episode may go without news before it is repeated.
        max_retries: repeats of one episode before the batch fails with EpisodeFailed.
        executor: spun by the evaluator while it waits; None when another thread spins
            ``node``.
        trace: observe every step (light, cmd_turn, bearing), so that ``trace()`` works
            and each reported fitness is checked against the messages; off, one message
            per episode instead of three per step.
        workers: namespaces or fnmatch patterns (``/worker*``) of the worker pairs.
        capacity: most robots per episode on any worker (0: no limit but the ``ports`` a
            hardware bridge has).

    Raises:
        ValueError: both ``workers`` and ``robot_namespace`` given, or capacity < 0.
    """

    def __init__(self, node: Node, robot_namespace: str = '', controller_node: str = '',
                 robot_node: str = '', stall_timeout_s: float = 2.0, max_retries: int = 3,
                 executor: Executor | None = None, trace: bool = False,
                 workers: Sequence[str] = (), capacity: int = 0):
        if workers and (robot_namespace or controller_node or robot_node):
            raise ValueError('give either workers or robot_namespace (with controller_node '
                             f'and robot_node), not both: workers={list(workers)}, '
                             f'robot_namespace={robot_namespace!r}')
        if capacity < 0:
            raise ValueError(f'capacity must be >= 0 robots (0: no limit), got {capacity}')
        self.node = node
        self.stall_timeout_s = stall_timeout_s
        self.max_retries = max_retries
        self.executor = executor
        self.capacity = capacity
        self.dropped = Dropped(node)
        self.restarts = 0           # episode attempts that failed and were repeated
        self._ids = EpisodeIds()
        self._wake = Wake()
        self._observed = (LIGHT, CMD_TURN, BEARING) if trace else ()
        specs = list(workers) or [robot_namespace]
        self.patterns = [s for s in specs if is_pattern(s)]
        self.workers: dict[str, Worker] = {}
        for namespace in specs:
            if not is_pattern(namespace):
                self._add(namespace, controller_node, robot_node)

    def _add(self, namespace: str, controller_node: str = '', robot_node: str = '') -> Worker:
        worker = Worker(self.node, namespace, self._observed, self.dropped, self._wake,
                        controller_node, robot_node)
        self.workers[worker.name] = worker
        return worker

    # --- what the manager and scripts read ---------------------------------------------

    @property
    def first(self) -> Worker | None:
        """The first worker (the only one unless several are configured or found)."""
        return next(iter(self.workers.values()), None)

    @property
    def robot_node(self) -> str:
        return self.first.robot_node if self.first else ''

    @property
    def controller_node(self) -> str:
        return self.first.controller_node if self.first else ''

    @property
    def topics(self) -> dict[str, str]:
        return self.first.topics if self.first else {}

    @property
    def episodes(self) -> int:
        """Episode attempts started, on every worker."""
        return sum(w.episodes for w in self.workers.values())

    def worker_records(self) -> list[dict]:
        """Per worker: namespace, nodes, episodes, robots, failures, why it was dropped."""
        return [w.record() for w in self.workers.values()]

    # --- public ------------------------------------------------------------------------

    def __call__(self, genomes, seeds) -> np.ndarray:
        """Score one episode per genome.

        Args:
            genomes: (n, 20) genomes.
            seeds: (n,) episode seeds, integers in [0, 2**53).

        Returns:
            (n,) float64 fitness, equal to ``CoreEvaluator``'s for the same seeds.

        Raises:
            ValueError: bad genomes or seeds.  EpisodeFailed: an episode failed more than
            ``max_retries`` times, or no worker is there.
        """
        genomes, seeds = _batch(genomes, seeds)
        fitness = np.empty(len(seeds))

        def keep(chunk: Chunk, episode: Episode) -> None:
            fitness[chunk.lo:chunk.hi] = episode.fitness()
        self._run(genomes, seeds, keep)
        return fitness

    def trace(self, genomes, seeds) -> Trace:
        """The per-step record of the episodes ``__call__`` would score.

        Args:
            genomes, seeds: as for ``__call__`` (at least one).

        Returns:
            A ``core.task.Trace``: arrays (steps, n, ...), robots on axis 1.

        Raises:
            ValueError: the evaluator was made with ``trace=False``, or no genome.
        """
        if BEARING not in self._observed:
            raise ValueError('this evaluator was made with trace=False, so it does not see '
                             'the per-step messages a trace needs')
        genomes, seeds = _batch(genomes, seeds)
        if not len(seeds):
            raise ValueError('trace() needs at least one genome')
        parts: list[tuple[int, Episode]] = []
        self._run(genomes, seeds, lambda chunk, episode: parts.append((chunk.lo, episode)))
        values = [episode.values for _, episode in sorted(parts, key=lambda p: p[0])]
        cmd = np.concatenate([v[CMD_TURN] for v in values], axis=1)
        return Trace(np.concatenate([v[BEARING][..., 0] for v in values], axis=1),
                     np.concatenate([v[LIGHT] for v in values], axis=1),
                     np.ascontiguousarray(cmd[..., 0]), np.ascontiguousarray(cmd[..., 1]))

    def robot_parameters(self, timeout_s: float = 5.0, worker: Worker | None = None) -> dict:
        """A robot node's parameters, for the record of a run.

        Args:
            timeout_s: how long to wait for each answer.
            worker: whose robot node (default: the first worker's).

        Returns:
            Parameter name -> plain Python value.

        Raises:
            TimeoutError: no robot node known yet, or no answer in time.
        """
        worker = worker or self.first
        robot = worker.robot_client() if worker else None
        if robot is None:
            raise TimeoutError('no robot node is known yet')
        names_f = robot.list_parameters()
        if not self._wait(names_f.done, timeout_s):
            raise TimeoutError(f'no answer from {worker.robot_node}/list_parameters')
        names = list(names_f.result().result.names)
        values_f = robot.get_parameters(names)
        if not self._wait(values_f.done, timeout_s):
            raise TimeoutError(f'no answer from {worker.robot_node}/get_parameters')
        return {n: parameter_value_to_python(v) for n, v in zip(names, values_f.result().values)}

    def wait_ready(self, timeout_s: float = 30.0) -> None:
        """Block until every named worker (and, with patterns, at least one that matches)
        has its robot node and controller connected and answering a parameter request.

        A named worker still missing after ``timeout_s`` is used once it appears (with a
        warning now).

        Raises:
            TimeoutError: no worker is ready after ``timeout_s``.
        """
        def ready() -> bool:
            self._discover()
            ready = [w for w in self.workers.values() if w.ready(self.stall_timeout_s)]
            return len(ready) == len(self.workers) and bool(ready or not self.patterns)
        if self._wait(ready, timeout_s):
            return
        absent = {w.name: w.missing() or [f'an answer from the parameter services of '
                                          f'{w.robot_node} and {w.controller_node}']
                  for w in self.workers.values() if not w.ready(self.stall_timeout_s)}
        if not self.workers:
            raise TimeoutError(f'after {timeout_s} s no worker matches {self.patterns}')
        if len(absent) == len(self.workers):
            raise TimeoutError(f'after {timeout_s} s still waiting for: '
                               + '; '.join(sum(absent.values(), [])))
        self.node.get_logger().warning(f'starting without worker(s) {absent}: each is used '
                                       'once it is ready')

    # --- waiting -------------------------------------------------------------------------

    def _wait(self, done: Callable[[], bool], timeout_s: float | Callable[[], float],
              woken: bool = False) -> bool:
        """Wait until done(); ``timeout_s`` may be a function giving the current deadline,
        which may move later but never earlier (it is asked again only once it seems to
        have passed: asking after every callback took about 5% of a lockstep step).
        ``woken``: done() changes only when a callback sets ``_wake``."""
        start = time.monotonic()
        deadline = timeout_s if callable(timeout_s) else (lambda: start + timeout_s)
        end = deadline()
        while not done():
            left = end - time.monotonic()
            if left <= 0:
                end = deadline()
                left = end - time.monotonic()
            if left <= 0:
                return False
            if self.executor is not None and woken:
                # the executor's own loop runs until a callback has news: not back into
                # Python after each of a step's two callbacks
                self.executor.spin_until_future_complete(self._wake.arm(),
                                                         timeout_sec=min(left, 0.05))
            elif self.executor is not None:
                self.executor.spin_once(timeout_sec=min(left, 0.05))
            else:
                self._wake.wait(min(left, 0.05))
                self._wake.clear()
        return True

    # --- the pool ----------------------------------------------------------------------

    def _discover(self) -> None:
        """Add workers that match a pattern and have appeared in the graph."""
        if self.patterns:
            for namespace in discover(self.node, self.patterns):
                if namespace not in self.workers:
                    self._add(namespace)

    def _pool(self) -> list[Worker]:
        """The workers to use for the next batch: every live one that is ready, after
        finding new ones and taking back dropped ones that answer again."""
        self._discover()
        log = self.node.get_logger()
        for worker in self.workers.values():
            if worker.state is WorkerState.LOST and worker.answers(self.stall_timeout_s):
                worker.rejoin()
                log.warning(f'worker {worker.name} answers again: back in the pool')
        for worker in self.workers.values():
            if worker.check_joined(self.stall_timeout_s) and len(self.workers) > 1:
                log.info(f'worker {worker.name} ({worker.robot_node}) joined')
        live = [w for w in self.workers.values() if w.state is WorkerState.READY]
        if live:
            return live
        # none ready: try the ones still joining anyway
        joining = [w for w in self.workers.values() if w.state is WorkerState.JOINING]
        if not joining:
            raise EpisodeFailed(f'no worker matches {self.patterns}: no node publishes '
                                f'<namespace>/{LIGHT} in a matching namespace')
        return joining

    def _share(self, chunk: Chunk, workers: list[Worker]) -> None:
        """Queue ``chunk`` on ``workers`` by their measured cost, cut to their capacity.  A
        worker not measured yet counts as the best of the others, so it gets a share
        and is measured."""
        known = [w.cost.model for w in workers if w.cost.model]
        default = tuple(np.min(known, axis=0)) if known else (0.0, 1.0)
        queues = schedule.plan(chunk.lo, chunk.hi, [(w.cost.model or default,
                                                     self._capacity(w)) for w in workers])
        for worker, queue in zip(workers, queues):
            worker.queue.extend(Chunk(lo, hi, chunk.attempts) for lo, hi in queue)

    def _capacity(self, worker: Worker) -> int | None:
        limits = [c for c in (self.capacity, worker.capacity) if c]
        return min(limits) if limits else None

    # --- one batch ---------------------------------------------------------------------

    def _run(self, genomes: np.ndarray, seeds: np.ndarray,
             keep: Callable[[Chunk, Episode], None]) -> None:
        """Run the batch's episodes, handing each finished one to ``keep``."""
        if not len(seeds):
            return
        live = self._pool()
        try:
            self._share(Chunk(0, len(seeds)), live)
            self._drive(live, genomes, seeds, keep)
        finally:
            for worker in self.workers.values():
                worker.queue.clear()
                worker.release()

    def _drive(self, live: list[Worker], genomes: np.ndarray, seeds: np.ndarray,
               keep: Callable[[Chunk, Episode], None]) -> None:
        left, steps = len(seeds), {}
        while left:
            for worker in live:
                if not worker.busy and (worker.queue or self._steal(worker, live)):
                    worker.begin(worker.queue.popleft(), genomes, self._ids)
            busy = [w for w in live if w.busy]
            news = False
            for worker in busy:
                outcome = worker.poll(seeds, self.stall_timeout_s)
                if outcome is None:
                    continue
                news = True
                status, reason = outcome
                if status == DONE:
                    self._check_steps(steps, worker)
                    keep(worker.chunk, worker.episode)
                    left -= worker.chunk.robots
                    worker.release()
                elif status == TOO_LARGE:
                    chunk = worker.chunk
                    worker.release()
                    worker.queue.extendleft(reversed([Chunk(lo, hi, chunk.attempts) for lo, hi
                                                      in schedule.pieces(chunk.lo, chunk.hi,
                                                                         worker.capacity)]))
                else:
                    live = self._failed(worker, reason, live)
            if not news:
                self._wait(lambda: any(w.news() for w in busy),
                           lambda: min(w.deadline(self.stall_timeout_s) for w in busy),
                           woken=True)

    def _steal(self, thief: Worker, live: list[Worker]) -> bool:
        """Move the last queued chunk of the worker with most robots queued to ``thief``
        (cut to its capacity); False when nothing is queued anywhere."""
        victim = max(live, key=lambda w: sum(c.robots for c in w.queue))
        if not victim.queue:
            return False
        chunk = victim.queue.pop()
        parts = schedule.pieces(chunk.lo, chunk.hi, self._capacity(thief))
        victim.queue.extend(Chunk(lo, hi, chunk.attempts) for lo, hi in parts[:-1])
        thief.queue.append(Chunk(*parts[-1], chunk.attempts))
        return True

    def _check_steps(self, steps: dict[str, int], worker: Worker) -> None:
        """Every episode of a batch must have as many steps, else fitness would differ."""
        steps[worker.name] = worker.episode.steps
        if len(set(steps.values())) > 1:
            raise EpisodeFailed(f'the workers run episodes of different lengths {steps}: '
                                'give every robot node the same steps (and parameters)')

    def _failed(self, worker: Worker, reason: str, live: list[Worker]) -> list[Worker]:
        """Repeat a failed episode with the same seeds: on the other workers when there are
        any (this one leaves the pool), else on this one.  Returns the live workers."""
        chunk = worker.chunk
        chunk.attempts += 1
        if chunk.attempts > self.max_retries:
            raise EpisodeFailed(f'an episode of {chunk.robots} robots failed '
                                f'{chunk.attempts} times; last: {reason}. Are the robot '
                                f'node ({worker.topics[LIGHT]}) and {worker.controller_node} '
                                'running?')
        self.restarts += 1
        log = self.node.get_logger()
        others = [w for w in live if w is not worker]
        if not others:
            worker.failures += 1
            worker.release()
            worker.queue.appendleft(chunk)
            log.warning(f'episode of {chunk.robots} robots, attempt {chunk.attempts}/'
                        f'{self.max_retries + 1}: {reason}; starting it again under a new '
                        'episode id')
            return live
        held = worker.drop(reason)
        log.error(f'worker {worker.name} dropped from the pool: {reason}; its '
                  f'{sum(c.robots for c in held)} robots of this batch go to '
                  f'{", ".join(w.name for w in others)} (same seeds, new episode ids)')
        for part in held:
            self._share(part, others)
        return others


def _batch(genomes, seeds) -> tuple[np.ndarray, np.ndarray]:
    """Checked (n, 20) genomes and (n,) int64 seeds, or a ValueError naming the problem."""
    genomes = check_genomes(genomes) if np.size(genomes) else np.empty((0, GENES))
    seeds = np.asarray(seeds, dtype=np.int64).reshape(-1)
    if seeds.shape != (len(genomes),):
        raise ValueError(f'need one seed per genome: {len(genomes)} genomes, '
                         f'{seeds.size} seeds')
    bad = (seeds < 0) | (seeds >= protocol.MAX_SEED)
    if bad.any():
        raise ValueError(f'episode seeds must be integers in [0, 2**53), got {seeds[bad][0]}')
    return genomes, seeds
