"""Reproduce a recording's protocol in the simulator.

Stationary data: every (episode, condition, heading) run is simulated at the
same heading, in the world of its condition (the manifest's world parameters
laid over the simulator's), for the same steps.  Where the light model cannot
describe the data (not 8 channels, headings unknown, or conditions that give no
world parameters) the simulated base values are the recording's own cell means
("observed" base): noise, correlation and time structure can still be
compared, levels cannot.  Closed-loop data: the manifest's genome runs the same
number of episodes per condition under the simulator's task.

``replicates`` > 1 simulates that many independent copies (as extra episodes),
which makes the simulated statistics more precise than the real ones.
"""
from __future__ import annotations

import dataclasses
import functools

import numpy as np

from ..core import network
from ..core.khepera import DARK, SENSORS, World, to_tenths
from ..core.noise import NoiseModel
from ..recording import Recording
from .simconfig import WORLD_KEYS, SimConfig
from .simulate import EffectEpisodes, stationary

BASES = ('auto', 'model', 'observed')


class ProtocolError(ValueError):
    """The recording cannot be reproduced in the simulator; the message says why."""


def kind(rec: Recording) -> str:
    """'stationary' or 'closed_loop': the manifest's protocol, else whether turns are known."""
    declared = rec.manifest.get('protocol')
    if declared in ('stationary', 'closed_loop'):
        return declared
    return 'closed_loop' if np.isfinite(rec.direction).any() else 'stationary'


@functools.lru_cache(maxsize=64)
def light_table(world: World, rounded: bool = True) -> np.ndarray:
    """The world's light table, computed once per world (unrounded for a noise model that
    rounds the reading at the end)."""
    return world.light_table(rounded)


def condition_world(rec: Recording, label: str, base: World) -> World:
    params = rec.manifest.get('conditions', {}).get(label) or {}
    given = {k: float(v) for k, v in params.items() if k in WORLD_KEYS} \
        if isinstance(params, dict) else {}
    try:
        return dataclasses.replace(base, **given)
    except ValueError as exc:
        raise ProtocolError(f'condition {label!r}: {exc}') from None


def base_mode(rec: Recording, requested: str = 'auto') -> tuple[str, str]:
    """('model' or 'observed', why)."""
    if requested not in BASES:
        raise ValueError(f'base must be one of {BASES}, got {requested!r}')
    reasons = []
    if rec.channels != SENSORS:
        reasons.append(f'the recording has {rec.channels} channels, the light model '
                       f'{SENSORS}')
    if not np.isfinite(rec.heading_deg).all():
        reasons.append('headings are not all known')
    conditions = rec.manifest.get('conditions', {})
    vague = [c for c in rec.conditions()
             if not (isinstance(conditions.get(c), dict) and set(conditions[c]) & set(WORLD_KEYS))]
    if vague:
        reasons.append(f'conditions {vague} give no world parameters ({", ".join(WORLD_KEYS)})')
    if requested == 'model' and reasons:
        raise ProtocolError('cannot use the light model: ' + '; '.join(reasons))
    if requested == 'observed' or reasons:
        return 'observed', '; '.join(reasons) or 'requested'
    return 'model', 'the light model at the recorded headings'


def replay(rec: Recording, config: SimConfig, effects=(), seed: int = 0, replicates: int = 1,
           base: str = 'auto') -> Recording:
    """A simulated recording of ``rec``'s protocol under ``config`` plus ``effects``."""
    effects = tuple(config.effects) + tuple(effects)
    if kind(rec) == 'closed_loop':
        return _closed_loop(rec, config, effects, seed, replicates)
    return _stationary(rec, config, effects, seed, replicates, _mode(rec, base))


_MODES: dict = {}


def _mode(rec: Recording, requested: str) -> str:
    """``base_mode(rec, requested)[0]``, found once per recording."""
    hit = _MODES.get((id(rec), requested))
    if hit is not None and hit[0] is rec:
        return hit[1]
    mode = base_mode(rec, requested)[0]
    if len(_MODES) > 64:
        _MODES.clear()
    _MODES[(id(rec), requested)] = (rec, mode)
    return mode


_RUNS: dict = {}


def runs(rec: Recording) -> list[np.ndarray]:
    """Sample indices of each (episode, condition, heading) run, in step order (read-only;
    found once per set of index columns: every replay of a recording shares them)."""
    cols = (rec.episode, rec.step, rec.heading_deg, rec.condition)
    key = tuple(id(c) for c in cols)
    hit = _RUNS.get(key)
    if hit is not None and all(a is b for a, b in zip(hit[0], cols)):
        return list(hit[1])
    out = _runs(rec)
    for r in out:
        r.flags.writeable = False
    if len(_RUNS) > 32:
        _RUNS.clear()
    _RUNS[key] = (cols, out)
    return list(out)


def _runs(rec: Recording) -> list[np.ndarray]:
    heading = np.nan_to_num(np.round(rec.heading_deg, 1), nan=1e9)
    _, cond = np.unique(rec.condition, return_inverse=True)
    order = np.lexsort((rec.step, heading, cond, rec.episode))
    key = np.stack([rec.episode[order], cond[order], heading[order]], axis=1)
    edges = np.flatnonzero((np.diff(key, axis=0) != 0).any(axis=1)) + 1
    return np.split(order, edges) if order.size else []


def _stationary(rec, config, effects, seed, replicates, mode) -> Recording:
    """Each episode is simulated as one continuous run through its headings and conditions,
    so effects with memory (drift, latency) carry over from one heading to the next."""
    light, noise, scale = _light(rec, config, mode)
    tiled, step, column = _copies(rec, light, replicates)
    sim = stationary(tiled, noise, effects, seed=seed)
    if scale != 1.0:
        sim = sim * scale
    return _indexed(rec, replicates, sim[step, :, column])


_COPIES: dict = {}


def _copies(rec: Recording, light: np.ndarray, replicates: int) -> tuple:
    """(the light of ``replicates`` copies side by side, read-only; per replayed sample its
    step and column in it), made once per recording, light and number of copies."""
    key = (id(rec), id(light), replicates)
    hit = _COPIES.get(key)
    if hit is not None and hit[0] is rec and hit[1] is light:
        return hit[2]
    episodes, column = np.unique(rec.episode, return_inverse=True)
    tiled = np.tile(light, (1, 1, replicates))
    tiled.flags.writeable = False
    out = (tiled, np.tile(rec.step, replicates),
           np.concatenate([column + k * episodes.size for k in range(replicates)]))
    if len(_COPIES) > 16:
        _COPIES.clear()
    _COPIES[key] = (rec, light, out)
    return out


_INDEX: dict = {}


def _indexed(rec: Recording, replicates: int, readings: np.ndarray) -> Recording:
    """A replay of stationary ``rec``: its index columns (episode, step, heading,
    condition) are built once per recording and number of copies and shared by every
    replay, so statistics can reuse their layout (``statistics._layout``)."""
    key = (id(rec), replicates)
    hit = _INDEX.get(key)
    if hit is None or hit[0] is not rec:
        everything = np.arange(len(rec))
        parts = [_rows(rec, everything, None, k) for k in range(replicates)]
        cols = {k: np.concatenate([p[k] for p in parts]) for k in parts[0] if k != 'readings'}
        manifest = {k: v for k, v in rec.manifest.items() if k not in ('source', 'samples',
                                                                       'lost_steps')}
        manifest['source'] = 'simulator'
        if len(_INDEX) > 64:
            _INDEX.clear()
        hit = _INDEX[key] = (rec, cols, manifest)
    return Recording(**hit[1], readings=readings, manifest=dict(hit[2]))


_LIGHT: dict = {}


def _light(rec: Recording, config: SimConfig, mode: str) -> tuple:
    """(samples, channels, episodes) light of every step of ``rec``'s episodes, the noise
    model to use and the scale of the readings; computed once per recording and
    configuration (every replay of a protocol sees the same light)."""
    key = (id(rec), config.world, config.noise, mode)
    hit = _LIGHT.get(key)
    if hit is not None and hit[0] is rec:
        return hit[1]
    episodes, column = np.unique(rec.episode, return_inverse=True)
    length = int(rec.step.max()) + 1
    light = np.full((length, rec.channels, episodes.size), np.nan)
    if mode == 'model':
        rounded = config.noise.rounding == 'level'
        tables = {label: light_table(condition_world(rec, label, config.world), rounded)
                  for label in rec.conditions()}
        for label, table in tables.items():
            at = rec.condition == label
            light[rec.step[at], :, column[at]] = table[:, to_tenths(rec.heading_deg[at])].T
        noise, scale = config.noise, 1.0
    else:
        for r in runs(rec):
            light[rec.step[r], :, column[r[0]]] = np.nan_to_num(rec.readings[r].mean(axis=0))
        scale = max(1.0, float(np.nanmax(light)) / DARK)    # the model's noise is proportional
        noise = _noise_within(config.noise, rec.channels)
    out = (_hold(light) / scale, noise, scale)
    if len(_LIGHT) > 64:
        _LIGHT.clear()
    _LIGHT[key] = (rec, out)
    return out


def _hold(light: np.ndarray) -> np.ndarray:
    """Fill steps a recording lacks with the light of the last step it has (else the next)."""
    for t in range(1, light.shape[0]):
        gap = np.isnan(light[t])
        light[t][gap] = light[t - 1][gap]
    for t in range(light.shape[0] - 2, -1, -1):
        gap = np.isnan(light[t])
        light[t][gap] = light[t + 1][gap]
    return np.nan_to_num(light)


def _noise_within(noise: NoiseModel, channels: int) -> NoiseModel:
    """The model with its dependence groups cut to the channels the data has."""
    groups = tuple(g for g in (tuple(s for s in grp if s < channels) for grp in noise.groups)
                   if g)
    return dataclasses.replace(noise, groups=groups)


def _rows(rec: Recording, r: np.ndarray, readings: np.ndarray, replicate: int) -> dict:
    offset = replicate * (int(rec.episode.max()) + 1)
    return {'episode': rec.episode[r] + offset, 'step': rec.step[r],
            'heading_deg': rec.heading_deg[r], 'condition': rec.condition[r],
            'readings': readings, 'direction': np.full(r.size, np.nan),
            'power': np.full(r.size, np.nan)}


def _concat(parts: list[dict], rec: Recording, config: SimConfig) -> Recording:
    cols = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    manifest = {k: v for k, v in rec.manifest.items() if k not in ('source', 'samples',
                                                                   'lost_steps')}
    manifest['source'] = 'simulator'
    return Recording(**cols, manifest=manifest)


def genome_of(rec: Recording) -> np.ndarray:
    genome = rec.manifest.get('genome')
    if genome is None:
        raise ProtocolError('a closed-loop recording needs the controller genome in its '
                            'manifest (genome: [20 numbers]) to be reproduced')
    try:
        return network.check_genomes(genome)[0]
    except ValueError as exc:
        raise ProtocolError(f'manifest genome: {exc}') from None


def _closed_loop(rec, config, effects, seed, replicates) -> Recording:
    if rec.channels != SENSORS:
        raise ProtocolError(f'closed-loop replay needs the Khepera\'s {SENSORS} channels, '
                            f'the recording has {rec.channels}')
    genome = genome_of(rec)
    out = []
    for ci, label in enumerate(rec.conditions()):
        episodes = np.unique(rec.episode[rec.condition == label])
        steps = max(int(rec.step[rec.episode == e].max()) + 1 for e in episodes)
        task = dataclasses.replace(config.task, steps=steps)
        env = EffectEpisodes(condition_world(rec, label, config.world), config.noise, task,
                             effects)
        n = episodes.size * replicates
        seeds = np.random.SeedSequence([seed, ci]).generate_state(n, np.uint64) >> np.uint64(11)
        out.append(_run(env, genome, seeds.astype(np.int64), episodes, replicates, label,
                        int(rec.episode.max()) + 1))
    return _concat(out, rec, config)


def _run(env, genome, seeds, episodes, replicates, label, span) -> dict:
    n = seeds.size
    w = network.unpack(np.repeat(genome[None], n, axis=0))
    readings = env.reset(seeds)
    rows = []
    while readings is not None:
        direction, power = network.act(w, readings)
        rows.append((env.step_index, env.bearing_deg.copy(), readings.copy(), direction,
                     power))
        readings = env.step(direction, power)
    t = len(rows)
    episode = np.concatenate([episodes + k * span for k in range(replicates)])
    return {'episode': np.repeat(episode, t),
            'step': np.tile(np.arange(t), n),
            'heading_deg': np.stack([r[1] for r in rows], axis=1).ravel(),
            'condition': np.full(n * t, label),
            'readings': np.stack([r[2] for r in rows], axis=1).reshape(n * t, SENSORS)
            .astype(np.float64),
            'direction': np.stack([r[3] for r in rows], axis=1).ravel().astype(np.float64),
            'power': np.stack([r[4] for r in rows], axis=1).ravel().astype(np.float64)}
