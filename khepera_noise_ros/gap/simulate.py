"""The simulator with unmodelled effects added: closed-loop episodes and stationary samples.

``EffectEpisodes`` is ``core.task.Episodes`` with the effects of ``gap.effects``
in its sensing and turning; with no effects it gives exactly the core's
episodes (same streams, same readings).  It is also the hook the simulator
node needs to honour its ``effects`` parameter.  ``stationary`` samples fixed
base values for any number of channels, for recordings of robots and boards the
light model does not describe.  Both honour the noise model's ``rounding``: with
'reading' the light level is not rounded before the noise; the effects of the
reading stage act on the unrounded sum, which is rounded and clipped once at the end.
With either, the level is not clipped before the noise: the reading saturates once.
"""
from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from ..core.khepera import DARK, SENSORS, TENTHS, World, to_tenths
from ..core.noise import NoiseModel
from ..core.task import Episodes, Task
from ..core.streams import UNIT
from . import draws


def _staged(effects, stage: str) -> list:
    return [e for e in effects if e.stage == stage]


def _entropy(seed) -> list[int]:
    """Seed material for the effects' generator, distinct from the core's streams."""
    return [int(s) for s in np.atleast_1d(np.asarray(seed, np.int64)).tolist()] + [0x6A9]


class EffectEpisodes(Episodes):
    """Core episodes plus effects; effects draw from their own generator seeded by ``seed``.

    The core's own sensing runs unchanged: the effects ride in a wrapper around the
    noise model (light stage before its noise, reading stage after), a turn's error
    is added to the bearing before the core applies the commanded turn, and a turn
    scale that also moves the knocks scales the task's perturbation.
    """

    def __init__(self, world: World = World(), noise: NoiseModel = NoiseModel(),
                 task: Task = Task(), effects=()):
        self.effects = tuple(effects)
        self._light: list = []
        self._reading: list = []
        self._turning: list = []
        super().__init__(world, noise, task)

    @property
    def task(self) -> Task:
        """The task, its knocks scaled by the turn effects that move them (the wheels make
        the knocks on a real robot); setting it sets the unscaled task."""
        scale = math.prod(e.scale for e in _staged(self.effects, 'turn')
                          if getattr(e, 'knocks', False))
        if scale == 1.0:
            return self._task
        return dataclasses.replace(self._task, perturbation_deg=float(
            min(180.0, self._task.perturbation_deg * scale)))

    @task.setter
    def task(self, task: Task) -> None:
        self._task = task

    @property
    def noise(self) -> 'EffectNoise':
        return self._noise

    @noise.setter
    def noise(self, model) -> None:
        """A new noise model keeps the effects (and their state) of the running episodes."""
        model = getattr(model, 'model_noise', model)
        self._noise = EffectNoise(model, self._light, self._reading)

    def reset(self, seed, robots: int | None = None, bearing_deg=None) -> np.ndarray:
        """Start episodes; the effects (``self.effects`` now) start afresh too."""
        n = robots if robots is not None else np.size(seed)
        # no effects: no generator to build (3 ms from 1024 seeds), exactly core Episodes
        rng = np.random.default_rng(_entropy(seed)) if self.effects else None
        self._light = [e.process(n, SENSORS, rng) for e in _staged(self.effects, 'light')]
        self._reading = [e.process(n, SENSORS, rng) for e in _staged(self.effects, 'reading')]
        self._turning = [e.process(n, SENSORS, rng) for e in _staged(self.effects, 'turn')]
        self.noise = self._noise
        return super().reset(seed, robots, bearing_deg)

    def step(self, direction, power) -> np.ndarray | None:
        if self._turning and not self.done:
            commanded = np.asarray(direction, np.float64) * np.asarray(power) \
                * self.world.deg_per_power
            actual = commanded
            for turn in self._turning:
                actual = turn(actual)
            self._bearing = (self._bearing + to_tenths(actual - commanded)) % TENTHS
        return super().step(direction, power)


class EffectNoise:
    """The model's noise with light-stage effects before it and reading-stage after.

    Duck-types ``NoiseModel`` for ``Episodes``: every other attribute is the model's.
    """

    def __init__(self, model_noise: NoiseModel, light: list, reading: list):
        self.model_noise = model_noise
        self.light, self.reading = light, reading

    def __getattr__(self, name):
        return getattr(self.model_noise, name)

    def apply(self, base, sensor_draws, group_draws, out=None) -> np.ndarray:
        if not (self.light or self.reading):
            return self.model_noise.apply(base, sensor_draws, group_draws, out=out)
        readings = sense(np.asarray(base, np.float64), self.model_noise, sensor_draws,
                         group_draws, self.light, self.reading).astype(np.float32)
        if out is None:
            return readings
        out[...] = readings
        return out


def sense(base: np.ndarray, noise: NoiseModel, sensor_draws, group_draws, light: list,
          reading: list) -> np.ndarray:
    """Light-stage effects, the model's noise on the light level (integer unless the
    reading is rounded at the end), reading stage."""
    level = base
    for apply in light:
        level = apply(level)
    if _rounds_level(noise):
        # rounded, not clipped: the converter saturates the noisy reading (``_levels``)
        level = np.rint(level).astype(np.float32)
        out = noise.apply(level, sensor_draws, group_draws).astype(np.float64)
    else:
        out = noise.added(np.asarray(level, np.float32), sensor_draws,
                          group_draws).astype(np.float64)
    for apply in reading:
        out = apply(out)
    return np.clip(np.rint(out), 0.0, DARK)


def stationary(base: np.ndarray, noise: NoiseModel, effects=(), seed: int = 0) -> np.ndarray:
    """(samples, channels, units) readings of units whose light is ``base`` at each sample,
    (samples, channels, units): each unit is one continuous run (effects keep their state).

    The whole run is computed at once: each effect's ``over_time`` acts on every sample
    (a drift as a filter over time), then the model's noise on every sample together.
    The model's dependence groups must lie within the channels; effects may name any.
    """
    samples, channels, robots = base.shape
    rng = draws.Remembered(_entropy(seed))    # the generator, its draws remembered
    rounded = _rounds_level(noise)
    light = _staged(effects, 'light')
    if light or base.flags.writeable:
        level = np.asarray(base, np.float64)
        for e in light:
            level = e.over_time(level, rng)
        flat = _levels(level, rounded)
    else:                       # a read-only base (a replay's light): its levels once
        flat = _held_levels(base, rounded)
    groups = max(1, len(noise.groups))
    d = _draws(int(seed), samples, channels + groups, robots)
    kernel = noise.apply if rounded else noise.added
    out = kernel(flat, d[:channels], d[channels:]).astype(np.float64)
    out = out.reshape(channels, samples, robots).transpose(1, 0, 2)
    for e in _staged(effects, 'reading'):
        out = e.over_time(out, rng)
    out = np.rint(out)                    # a new array: clipped in place
    return np.clip(out, 0.0, DARK, out=out)


@functools.lru_cache(maxsize=8)
def _draws(seed: int, samples: int, rows: int, robots: int) -> np.ndarray:
    """The model's noise draws of ``stationary``, (rows, samples x robots), read-only: they
    depend on the seed and the shape alone (not on the effects), and every replay of a
    protocol with one seed uses the same."""
    draws = np.random.default_rng([seed, 0x5A7]).integers(
        0, int(UNIT) + 1, size=(samples, rows, robots), dtype=np.uint16)
    out = np.ascontiguousarray(draws.transpose(1, 0, 2)).reshape(rows, -1)
    out.flags.writeable = False
    return out


def _rounds_level(noise) -> bool:
    return getattr(noise, 'rounding', 'level') == 'level'


def _levels(level: np.ndarray, rounded: bool = True) -> np.ndarray:
    """(channels, samples x units) float32 light levels the model's noise acts on: rounded
    unless the reading is rounded at the end, never clipped.  A light-stage effect (a
    gain, a flicker) can take the light beyond what the converter reads; the converter
    saturates the noisy reading once, at the end, as a sensor does.  (Clipped before the
    noise, a level beyond the range read the range's end plus noise, and half of those
    readings fell back inside it.)"""
    if rounded:
        level = np.rint(level)
    level = level.astype(np.float32)
    return np.ascontiguousarray(level.transpose(1, 0, 2)).reshape(level.shape[1], -1)


_HELD: dict = {}


def _held_levels(base: np.ndarray, rounded: bool = True) -> np.ndarray:
    """``_levels`` of a read-only ``base``, made once (read-only too)."""
    hit = _HELD.get((id(base), rounded))
    if hit is not None and hit[0] is base:
        return hit[1]
    flat = _levels(np.asarray(base, np.float64), rounded)
    flat.flags.writeable = False
    if len(_HELD) > 8:
        _HELD.clear()
    _HELD[(id(base), rounded)] = (base, flat)
    return flat
