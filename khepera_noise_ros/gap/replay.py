"""A recording's protocol reproduced in the simulator (stationary: one continuous run per
episode; closed loop: the manifest's genome), in the world of each condition."""
from __future__ import annotations

import dataclasses
from typing import Any, Callable, Sequence

import numpy as np

from ..core import network
from ..core.khepera import DARK, SENSORS, to_tenths
from ..core.noise import NoiseModel
from ..effects import Effect, Stage
from ..effects.base import Array
from ..effects.simulate import EffectEpisodes, SimCache, light_table, staged, stationary
from ..memo import Recent
from ..recording import Recording
from .protocol import (ProtocolError, base_mode, calibrating, condition_world, genome_of, kind,
                       runs)
from ..simconfig import SimConfig

Tiled = tuple[Array, np.ndarray, dict[str, Any], NoiseModel, float]


class Replayer:
    """Replays of one recording's protocol under one configuration.  What every replay
    shares (the light of each step, the index columns of each number of copies) is made
    once and kept here; the replays' index columns are shared arrays, never modified."""

    def __init__(self, rec: Recording, config: SimConfig, base: str = 'auto',
                 cache: SimCache | None = None):
        self.rec, self.config, self.kind = rec, config, kind(rec)
        self.mode = base_mode(rec, base)[0] if self.kind == 'stationary' else 'model'
        self.episodes, self.column = np.unique(rec.episode, return_inverse=True)
        self.span = int(rec.episode.max()) + 1      # copy k's episodes numbered k span on
        self.cache = cache if cache is not None else SimCache()
        self._lights: Recent[tuple[Effect, ...], tuple[Array, NoiseModel, float]] = Recent(8)
        self._copies: Recent[tuple[Any, ...], Tiled] = Recent(8)

    def replay(self, effects: Sequence[Effect] = (), seed: int = 0, copies: int = 1) -> Recording:
        effects = tuple(self.config.effects) + tuple(effects)
        if self.kind == 'closed_loop':
            return self._closed_loop(effects, seed, copies)
        shaped = tuple(staged(effects, Stage.WORLD)) if self.mode == 'model' else ()
        tiled, at, index, noise, scale = self._copies.recall(
            (copies, shaped), lambda: self._tiled(copies, shaped))
        sim = stationary(tiled, noise, effects, seed=seed, cache=self.cache)
        readings = sim.transpose(0, 2, 1).reshape(-1, sim.shape[1])[at]
        if scale != 1.0:              # no second copy of every replay at the model's scale
            readings = readings * scale
        return Recording(**index, readings=readings, manifest=self._manifest())

    def _light(self, shaped: tuple[Effect, ...]) -> tuple[Array, NoiseModel, float]:
        """(samples, channels, episodes) light of every step, the noise model, the scale,
        in the world the world-stage effects ``shaped`` make."""
        rec, config, column = self.rec, self.config, self.column
        light = np.full((int(rec.step.max()) + 1, rec.channels, self.episodes.size), np.nan)
        noise, scale = config.noise, 1.0
        if self.mode == 'model':
            rounded = config.noise.rounding == 'level'
            for label in rec.conditions():
                table = light_table(condition_world(rec, label, config.world), shaped, rounded)
                at = rec.condition == label
                light[rec.step[at], :, column[at]] = table[:, to_tenths(rec.heading_deg[at])].T
        else:
            for r in runs(rec):
                light[rec.step[r], :, column[r[0]]] = np.nan_to_num(rec.readings[r].mean(axis=0))
            scale = max(1.0, float(np.nanmax(light)) / DARK)   # the model's noise is relative
            groups = tuple(g for g in (tuple(s for s in grp if s < rec.channels)
                                       for grp in noise.groups) if g)
            noise = dataclasses.replace(noise, groups=groups)
        return _hold(light) / scale, noise, scale

    def _tiled(self, copies: int, shaped: tuple[Effect, ...]) -> Tiled:
        """The light of ``copies`` copies side by side; per replayed sample its row of the
        light's (step, column) rows; the index columns (arrays read-only); noise model, scale."""
        rec, span = self.rec, self.span
        light, noise, scale = self._lights.recall(shaped, lambda: self._light(shaped))
        tiled = np.tile(light, (1, 1, copies))
        index = {'episode': np.concatenate([rec.episode + k * span for k in range(copies)]),
                 'step': np.tile(rec.step, copies),
                 'heading_deg': np.tile(rec.heading_deg, copies),
                 'condition': np.tile(rec.condition, copies),
                 'direction': np.full(len(rec) * copies, np.nan),
                 'power': np.full(len(rec) * copies, np.nan)}
        for value in (tiled, *index.values()):
            value.flags.writeable = False
        at = np.tile(rec.step, copies) * tiled.shape[2] + np.concatenate(
            [self.column + k * self.episodes.size for k in range(copies)])
        return tiled, at, index, noise, scale

    def _manifest(self) -> dict[str, Any]:
        return {**{k: v for k, v in self.rec.manifest.items()
                   if k not in ('source', 'samples', 'lost_steps')}, 'source': 'simulator'}

    def _closed_loop(self, effects: tuple[Effect, ...], seed: int, copies: int) -> Recording:
        rec, config = self.rec, self.config
        if rec.channels != SENSORS:
            raise ProtocolError(f"closed-loop replay needs the Khepera's {SENSORS} channels, "
                                f'the recording has {rec.channels}')
        calibration = calibrating(rec)      # the protocol's commands, no genome
        genome = None if calibration else genome_of(rec)
        parts = []
        for ci, label in enumerate(rec.conditions()):
            episodes_ = np.unique(rec.episode[rec.condition == label])
            steps = max(int(rec.step[rec.episode == e].max()) + 1 for e in episodes_)
            task = dataclasses.replace(config.task, steps=steps)
            if calibration:
                task = dataclasses.replace(task, perturbation_deg=0.0)
            env = EffectEpisodes(condition_world(rec, label, config.world), config.noise, task,
                                 effects)
            seeds = (np.random.SeedSequence([seed, ci]).generate_state(
                episodes_.size * copies, np.uint64) >> np.uint64(11)).astype(np.int64)
            ids = np.concatenate([episodes_ + k * self.span for k in range(copies)])
            if genome is None:
                parts.append(run_calibration(env, rec, episodes_, seeds, ids, label))
            else:
                w = network.unpack(np.repeat(genome[None], seeds.size, axis=0))
                parts.append(_episodes(env, seeds, None, lambda t, x: network.act(w, x), ids,
                                       label))
        cols = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
        return Recording(**cols, manifest=self._manifest())


def _episodes(env: EffectEpisodes, seeds: np.ndarray, bearing_deg: Array | None,
              command: Callable[[int, Array], tuple[Any, Any]], episode: np.ndarray,
              label: str) -> dict[str, np.ndarray]:
    """The columns of ``env``'s episodes from ``seeds`` with the (direction, power) of
    ``command`` at each step, the episodes numbered ``episode``."""
    readings: Array | None = env.reset(seeds, bearing_deg=bearing_deg)
    rows: list[tuple[Any, ...]] = []
    while readings is not None:
        direction, power = command(len(rows), readings)
        rows.append((env.bearing_deg.copy(), readings.copy(), direction, power))
        readings = env.step(direction, power)
    heading, x, direction, power = (np.stack(column, axis=1) for column in zip(*rows))
    n, t = seeds.size, len(rows)
    return {'episode': np.repeat(episode, t), 'step': np.tile(np.arange(t), n),
            'heading_deg': heading.ravel(), 'condition': np.full(n * t, label),
            'readings': x.reshape(n * t, -1).astype(np.float64),
            'direction': direction.ravel().astype(np.float64),
            'power': power.ravel().astype(np.float64)}


def _hold(light: Array) -> Array:
    """Fill steps a recording lacks with the light of the last step it has (else the next)."""
    for view in (light, light[::-1]):
        for t in range(1, view.shape[0]):
            gap = np.isnan(view[t])
            view[t][gap] = view[t - 1][gap]
    out: Array = np.nan_to_num(light)
    return out


def run_calibration(env: EffectEpisodes, rec: Recording, episodes: np.ndarray,
                    seeds: np.ndarray, ids: np.ndarray, label: str) -> dict[str, np.ndarray]:
    """The turn calibration's replay: the recorded commands of ``episodes`` (tiled over
    copies as ``seeds``) from each episode's recorded first heading, in ``env``."""
    steps = env.task.steps
    copies = seeds.size // episodes.size
    start = np.zeros(episodes.size)
    command = np.zeros((2, steps, episodes.size))
    command[0] = 1.0
    for i, e in enumerate(episodes):
        at = rec.episode == e
        first = np.argmin(np.where(at, rec.step, np.iinfo(np.int64).max))
        start[i] = np.nan_to_num(rec.heading_deg[first])
        s = rec.step[at]
        command[0, s, i] = np.nan_to_num(rec.direction[at], nan=1.0)
        command[1, s, i] = np.nan_to_num(rec.power[at])
    command = np.tile(command, (1, 1, copies))
    return _episodes(env, seeds, np.tile(start, copies), lambda t, _: (
        command[0, t].astype(np.int64), command[1, t].astype(np.int64)), ids, label)
