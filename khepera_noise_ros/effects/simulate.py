"""The simulator with effects added: closed-loop episodes and stationary runs.

``EffectEpisodes`` is ``core.task.Episodes`` with effects in its sensing and turning;
with no effects it gives exactly the core's episodes (same streams, same readings).  The
simulator node runs it for its ``effects`` parameter.  ``stationary`` simulates whole
runs at fixed light at once, for any number of channels.  Both honour the noise
model's ``rounding``: with 'reading' the light level is not rounded before the noise;
reading-stage effects act on the unrounded sum, which is rounded and clipped once.  The
level is never clipped before the noise: the converter saturates the reading once.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Sequence

import numpy as np

from ..core.khepera import DARK, SENSOR_ANGLES_DEG, SENSORS, TENTHS, World, to_tenths
from ..core.noise import NoiseModel
from ..core.streams import UNIT
from ..core.task import Episodes, Task
from ..memo import Recent
from .base import AnyArray, Array, Effect, Stage, Step


def staged(effects: Sequence[Effect], stage: Stage) -> list[Effect]:
    return [e for e in effects if e.stage is stage]


def entropy(seed: Any) -> list[int]:
    """Seed material for the effects' generator, distinct from the core's streams."""
    return [int(s) for s in np.atleast_1d(np.asarray(seed, np.int64)).tolist()] + [0x6A9]


class EffectEpisodes(Episodes):
    """Core episodes plus effects, which draw from their own generator seeded by the
    episodes' seed.  The light stage acts before the model's noise, the reading stage
    after it; a turn's error is added to the bearing before the core applies the
    commanded turn, and a turn scale that moves the knocks scales the task's knocks."""

    def __init__(self, world: World = World(), noise: NoiseModel = NoiseModel(),
                 task: Task = Task(), effects: Sequence[Effect] = ()):
        self.effects = tuple(effects)
        self._steps: dict[Stage, list[Step]] = {stage: [] for stage in Stage}
        self._knocking: list[Step] = []
        super().__init__(world, noise, task)

    @property
    def effects(self) -> tuple[Effect, ...]:
        return self._effects

    @effects.setter
    def effects(self, effects: Sequence[Effect]) -> None:
        """New effects remake the world's table (world-stage effects act there)."""
        self._effects = tuple(effects)
        if hasattr(self, '_world'):
            self.world = self._world

    @property
    def world(self) -> World:
        return self._world

    @world.setter
    def world(self, world: World) -> None:
        """The world with its table as the world-stage effects make it."""
        Episodes.world.fset(self, world)  # type: ignore[attr-defined]
        if staged(self.effects, Stage.WORLD):
            self._table, self._levels = (np.ascontiguousarray(
                light_table(world, self.effects, rounded).astype(np.float32).T)
                for rounded in (True, False))

    @property
    def task(self) -> Task:
        """The task, its knocks scaled by the turn effects that move them; setting it sets
        the unscaled task."""
        scale = math.prod(getattr(e, 'scale', 1.0) for e in staged(self.effects, Stage.ACTUATOR)
                          if getattr(e, 'knocks', False))
        if scale == 1.0:
            return self._task
        return dataclasses.replace(self._task, perturbation_deg=float(
            min(180.0, self._task.perturbation_deg * scale)))

    @task.setter
    def task(self, task: Task) -> None:
        self._task = task

    @property    # type: ignore[override]
    def noise(self) -> 'EffectNoise':
        return self._noise

    @noise.setter
    def noise(self, model: Any) -> None:
        """A new noise model keeps the effects (and their state) of the running episodes."""
        model = getattr(model, 'model_noise', model)
        self._noise = EffectNoise(model, self._steps[Stage.LIGHT], self._steps[Stage.READING])

    def reset(self, seed: Any, robots: int | None = None, bearing_deg: Any = None) -> Array:
        """Start episodes; the effects (``self.effects`` now) start afresh too."""
        n = robots if robots is not None else int(np.size(seed))
        rng = np.random.default_rng(entropy(seed))     # its own: the core's streams untouched
        self._steps = {stage: [e.start(n, SENSORS, rng) for e in staged(self.effects, stage)]
                       for stage in Stage}
        # the wheels of a turn effect that has them make the task's knocks as turns
        self._knocking = [step for e, step in zip(staged(self.effects, Stage.ACTUATOR),
                                                  self._steps[Stage.ACTUATOR])
                          if getattr(e, 'wheel_knocks', False) and getattr(e, 'knocks', False)]
        self.noise = self._noise
        return super().reset(seed, robots, bearing_deg)

    def step(self, direction: Any, power: Any) -> Array | None:
        if self._steps[Stage.ACTUATOR] and not self.done:
            commanded = np.asarray(direction, np.float64) * np.asarray(power) \
                * self.world.deg_per_power
            actual = commanded
            for turn in self._steps[Stage.ACTUATOR]:
                actual = turn(actual)
            self._bearing = (self._bearing + to_tenths(actual - commanded)) % TENTHS
        return super().step(direction, power)

    def _knocked(self, tenths: np.ndarray) -> np.ndarray:
        """A knock made by the wheels of the turn effects that make knocks."""
        if not self._knocking:
            return tenths
        deg = np.asarray(tenths, np.float64) / 10.0
        for turn in self._knocking:
            deg = turn(deg)
        return to_tenths(deg)


def light_table(world: World, effects: Sequence[Effect] = (), rounded: bool = False) -> Array:
    """(SENSORS, TENTHS) light of ``world`` at every bearing with the world-stage effects
    (rounded like ``World.light_table`` when ``rounded``)."""
    own = np.asarray(world.light_table(rounded), np.float64)
    shaped = staged(effects, Stage.WORLD)
    if not shaped:
        return own
    bearing = np.arange(TENTHS) / 10.0
    level = raw = world.response(bearing[None, :] - np.asarray(SENSOR_ANGLES_DEG)[:, None])
    for e in shaped:
        level = e.table(level, world)
    changed = (level != raw).any(axis=1)       # the other sensors: exactly the world's own
    own[changed] = np.rint(level[changed]) if rounded else level[changed]
    return own


class EffectNoise:
    """The model's noise with light-stage effects before it and reading-stage ones after;
    every other attribute is the model's (it stands in for a ``NoiseModel``)."""

    def __init__(self, model_noise: NoiseModel, light: list[Step], reading: list[Step]):
        self.model_noise = model_noise
        self.light, self.reading = light, reading

    def __getattr__(self, name: str) -> Any:
        return getattr(self.model_noise, name)

    def apply(self, base: AnyArray, sensor_draws: AnyArray, group_draws: AnyArray,
              out: AnyArray | None = None) -> AnyArray:
        if not (self.light or self.reading):
            return self.model_noise.apply(base, sensor_draws, group_draws, out=out)
        readings = sense(np.asarray(base, np.float64), self.model_noise, sensor_draws,
                         group_draws, self.light, self.reading).astype(np.float32)
        if out is None:
            return readings
        out[...] = readings
        return out


def sense(base: Array, noise: NoiseModel, sensor_draws: AnyArray, group_draws: AnyArray,
          light: list[Step], reading: list[Step]) -> Array:
    """Light-stage effects, the model's noise on the light level (integer unless the
    reading is rounded at the end), then the reading stage."""
    level = base
    for apply in light:
        level = apply(level)
    rounded = rounds_level(noise)
    kernel = noise.apply if rounded else noise.added
    level = np.rint(level) if rounded else level    # not clipped: the converter saturates
    out = kernel(np.asarray(level, np.float32), sensor_draws, group_draws).astype(np.float64)
    for apply in reading:
        out = apply(out)
    return np.clip(np.rint(out), 0.0, DARK)


def stationary(base: Array, noise: NoiseModel, effects: Sequence[Effect] = (), seed: int = 0,
               cache: SimCache | None = None) -> Array:
    """(samples, channels, units) readings of units whose light is ``base`` (of that
    shape) at each sample; each unit is one continuous run (effects keep their state).

    The whole run at once: each effect's ``over_time`` acts on every sample, then the
    model's noise on every sample together.  The model's dependence groups must lie
    within the channels; effects may name any.  ``cache``: draws and levels remembered
    across simulations of one protocol (the same numbers)."""
    cache = cache if cache is not None else SimCache()
    samples, channels, robots = base.shape
    rng = np.random.default_rng(entropy(seed))
    rounded = rounds_level(noise)
    light = staged(effects, Stage.LIGHT)
    if light:
        level = np.asarray(base, np.float64)
        for e in light:
            level = e.over_time(level, rng)
        flat = levels(level, rounded)
    else:
        flat = cache.levels(base, rounded)
    groups = max(1, len(noise.groups))
    d = cache.model_draws(int(seed), samples, channels + groups, robots)
    kernel = noise.apply if rounded else noise.added
    out = kernel(flat, d[:channels], d[channels:]).astype(np.float64)
    out = out.reshape(channels, samples, robots).transpose(1, 0, 2)
    reading = staged(effects, Stage.READING)
    for e in reading:
        out = e.over_time(out, rng)
    out = np.rint(out, out=None if reading else out)     # an array of its own: clipped in place
    return np.clip(out, 0.0, DARK, out=out)


def rounds_level(noise: Any) -> bool:
    return getattr(noise, 'rounding', 'level') == 'level'


def levels(level: Array, rounded: bool = True) -> AnyArray:
    """(channels, samples x units) float32 light levels the model's noise acts on: rounded
    unless the reading is rounded at the end, never clipped (a light-stage effect can
    take the light beyond what the converter reads; the converter saturates once)."""
    out = np.empty((level.shape[1], level.shape[0], level.shape[2]), np.float32)
    by_channel = level.transpose(1, 0, 2)
    if rounded:
        np.rint(by_channel, out=out)            # rounded in double precision, then single
    else:
        out[...] = by_channel
    return out.reshape(level.shape[1], -1)


class SimCache:
    """What stationary simulations of one protocol share, held by whoever repeats them (a
    diagnosis holds one): the model's noise draws per seed and shape (they do not depend
    on the effects) and the light levels of a read-only base, both read-only."""

    def __init__(self) -> None:
        self._model: Recent[tuple[int, ...], AnyArray] = Recent(8)
        self._levels: list[tuple[Array, bool, AnyArray]] = []

    def model_draws(self, seed: int, samples: int, rows: int, robots: int) -> AnyArray:
        """The model's noise draws, (rows, samples x robots)."""
        def make() -> AnyArray:
            draws = np.random.default_rng([seed, 0x5A7]).integers(
                0, int(UNIT) + 1, size=(samples, rows, robots), dtype=np.uint16)
            out = np.ascontiguousarray(draws.transpose(1, 0, 2)).reshape(rows, -1)
            out.flags.writeable = False
            return out
        return self._model.recall((seed, samples, rows, robots), make)

    def levels(self, base: Array, rounded: bool) -> AnyArray:
        """``levels`` of ``base``, made once where ``base`` is read-only (a replay's light)."""
        if base.flags.writeable:
            return levels(np.asarray(base, np.float64), rounded)
        for known, how, flat in self._levels:
            if known is base and how == rounded:
                return flat
        flat = levels(np.asarray(base, np.float64), rounded)
        flat.flags.writeable = False
        self._levels = self._levels[-7:] + [(base, rounded, flat)]
        return flat
