"""One episode as the evaluator sees it: ids, the chunk of robots, what has arrived."""
from __future__ import annotations

from dataclasses import dataclass
import secrets
import time

import numpy as np

from ..core.khepera import SENSORS
from ..core.task import step_fitness
from . import protocol
from .protocol import BEARING, CMD_TURN, LIGHT


class EpisodeFailed(RuntimeError):
    """An episode could not be completed through the graph."""


def episode_fitness(readings: np.ndarray, power: np.ndarray) -> np.ndarray:
    """Mean step fitness, summed in float32 step by step exactly as core.task.run does.

    readings: (steps, B, 8) float32; power: (steps, B).
    """
    total = np.zeros(readings.shape[1], np.float32)
    for step_readings, step_power in zip(readings, power):
        total += step_fitness(step_readings, step_power)
    return (total / len(readings)).astype(np.float64)


class EpisodeIds:
    """Episode ids that count up from a random start, so that two managers sharing a
    robot node almost surely use different ids."""

    def __init__(self):
        self._next = secrets.randbelow(protocol.MAX_EPISODE)

    def __next__(self) -> int:
        self._next = (self._next + 1) % protocol.MAX_EPISODE
        return self._next


class Episode:
    """What the evaluator has observed of one episode; filled by the subscription callbacks.

    ``topics``: the per-step topics observed (none unless tracing).  Each one's values go
    straight into a preallocated (steps, B, columns) array, in the dtype the core computes
    with (readings float32), so that nothing is stacked at the end.
    """

    LAYOUT = {LIGHT: (SENSORS, np.float32), CMD_TURN: (2, np.int32), BEARING: (1, np.float64)}

    def __init__(self, episode: int, robots: int, steps: int, topics: tuple[str, ...]):
        self.episode, self.robots, self.steps = episode, robots, steps
        self.values = {t: np.empty((steps, robots, self.LAYOUT[t][0]), self.LAYOUT[t][1])
                       for t in topics}
        self.seen = {t: np.zeros(steps, bool) for t in topics}
        self.score: np.ndarray | None = None       # the robot node's fitness, (B,)
        self.error: str | None = None
        self.complete = False
        self.progress = time.monotonic()
        self._count = 0

    @property
    def finished(self) -> bool:
        return self.complete or self.error is not None

    @property
    def next_step(self) -> int:
        """The first step some observed message is still missing for."""
        return min((int(np.argmin(seen)) if not seen.all() else self.steps
                    for seen in self.seen.values()), default=0)

    def fitness(self) -> np.ndarray:
        return self.score

    def add_fitness(self, steps: int, values: np.ndarray) -> None:
        if self.finished:
            return
        score = values[:, 0]
        if steps != self.steps:
            self.error = (f'fitness after {steps} steps, but the robot node has steps = '
                          f'{self.steps} (was it changed during the episode?)')
        elif score.shape[0] != self.robots:
            self.error = (f'fitness for episode {self.episode} has {score.shape[0]} robots, '
                          f'the episode has {self.robots}')
        elif self.score is None:
            self.score = score.copy()
            self.progress = time.monotonic()
            self._check_complete()
        elif not np.array_equal(self.score, score):
            self.error = (f'two different fitness messages for episode {self.episode}: two '
                          'robot nodes in one namespace?')

    def _check_complete(self) -> None:
        """Complete once the fitness and every observed step are in; then the fitness
        must be the one the observed readings and commands give."""
        if self.score is None or self._count < len(self.values) * self.steps:
            return
        if LIGHT in self.values and CMD_TURN in self.values:
            observed = episode_fitness(self.values[LIGHT], self.values[CMD_TURN][..., 1])
            if not np.array_equal(observed, self.score):
                robot = int(np.flatnonzero(observed != self.score)[0])
                self.error = (f'the robot node reports fitness {self.score[robot]} for robot '
                              f'{robot} of episode {self.episode}, its light and cmd_turn '
                              f'messages give {observed[robot]}')
                return
        self.complete = True

    def add(self, topic: str, step: int, values: np.ndarray) -> None:
        if self.finished or (topic == BEARING and step == self.steps):   # final heading
            return
        if values.shape[0] != self.robots:
            self.error = (f'{topic} ({self.episode}, {step}) has {values.shape[0]} robots, '
                          f'the episode has {self.robots}')
        elif step >= self.steps:
            self.error = (f'{topic} for step {step}, but the robot node has steps = '
                          f'{self.steps} (was it changed during the episode?)')
        elif not self.seen[topic][step]:
            self.values[topic][step] = values
            self.seen[topic][step] = True
            self.progress = time.monotonic()
            self._count += 1
            self._check_complete()
        elif not np.array_equal(self.values[topic][step],
                                values.astype(self.values[topic].dtype)):
            self.error = (f'two different {topic} messages for ({self.episode}, {step}): '
                          'a node answered twice with different data')


@dataclass
class Chunk:
    """Robots [lo, hi) of a batch, and how many times an episode of them failed."""

    lo: int
    hi: int
    attempts: int = 0

    @property
    def robots(self) -> int:
        return self.hi - self.lo
