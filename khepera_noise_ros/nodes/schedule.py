"""Splitting a batch of episodes across workers: shares by measured speed, episodes by capacity.

Every robot's episode depends only on its genome and its seed, so the split
decides how long a batch takes, never a fitness.  Ranges are ``(lo, hi)``
index pairs into the batch.

A lockstep step on a worker costs a fixed latency (the message round trip)
plus a cost per robot: ``seconds per step = latency + robots / speed``.  The
split gives each worker a share that makes all finish together, which is a
share in proportion to ``speed`` when the latencies are equal.  (Speed alone,
measured as robot-steps per second, would rate a worker that got a small
share as slow, and starve it.)
"""
from __future__ import annotations

from typing import Sequence

Range = tuple[int, int]
Model = tuple[float, float]               # (latency s per step, s per robot-step)


class Cost:
    """A worker's cost per step, fitted by least squares to its recent episodes (each
    older episode weighs ``memory`` times less)."""

    def __init__(self, memory: float = 0.8):
        self.memory = memory
        self._sums = [0.0] * 5              # weight, x, y, xx, xy; x robots, y s per step

    def add(self, robots: int, seconds_per_step: float) -> None:
        x, y = float(robots), float(seconds_per_step)
        self._sums = [self.memory * s + v
                      for s, v in zip(self._sums, (1.0, x, y, x * x, x * y))]

    @property
    def model(self) -> Model | None:
        """(latency, seconds per robot-step), or None before any episode."""
        w, sx, sy, sxx, sxy = self._sums
        if w == 0:
            return None
        mx, my = sx / w, sy / w
        var, cov = sxx / w - mx * mx, sxy / w - mx * my
        if var > 1e-9 * mx * mx and cov > 0 and my - cov / var * mx >= 0:
            return my - cov / var * mx, cov / var
        return 0.0, my / mx                 # one batch size so far: all cost per robot


def shares(total: int, models: Sequence[Model]) -> list[int]:
    """``total`` robots split so that every worker would finish at the same time
    (workers whose latency alone exceeds that time get none), in whole numbers by
    largest remainder, ties to the earlier worker."""
    if not models:
        raise ValueError('need at least one worker to share a batch among')
    if not all(c0 >= 0 and c1 > 0 for c0, c1 in models):
        raise ValueError(f'worker costs must be latency >= 0 and cost per robot > 0, got '
                         f'{list(models)}')
    active = sorted(range(len(models)), key=lambda i: models[i][0])
    while True:
        finish = (total + sum(models[i][0] / models[i][1] for i in active)) / sum(
            1 / models[i][1] for i in active)
        if len(active) == 1 or models[active[-1]][0] < finish:
            break
        active.pop()                        # too slow to start: the others finish first
    exact = [max(0.0, (finish - c0) / c1) if i in active else 0.0
             for i, (c0, c1) in enumerate(models)]
    scale = total / sum(exact) if sum(exact) else 0.0
    exact = [e * scale for e in exact]
    out = [int(e) for e in exact]
    by_remainder = sorted(range(len(models)), key=lambda i: (out[i] - exact[i], i))
    for i in by_remainder[:total - sum(out)]:
        out[i] += 1
    return out


def pieces(lo: int, hi: int, capacity: int | None) -> list[Range]:
    """[lo, hi) as consecutive episodes of at most ``capacity`` robots (None: one episode)."""
    if capacity is not None and capacity < 1:
        raise ValueError(f'capacity must be >= 1 robot or None, got {capacity}')
    step = hi - lo if capacity is None else capacity
    return [(i, min(i + step, hi)) for i in range(lo, hi, max(step, 1))]


def plan(lo: int, hi: int, workers: Sequence[tuple[Model, int | None]]) -> list[list[Range]]:
    """Each worker's episodes for [lo, hi): consecutive shares by ``shares``, each cut to
    the worker's capacity.  ``workers``: (cost model, capacity) pairs."""
    queues, start = [], lo
    for size, (_, capacity) in zip(shares(hi - lo, [m for m, _ in workers]), workers):
        queues.append(pieces(start, start + size, capacity))
        start += size
    return queues
