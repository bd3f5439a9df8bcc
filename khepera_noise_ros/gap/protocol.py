"""A recording's protocol: what kind it is, its runs and episodes, the world of each
condition, and whether the diagnosis can reproduce it (``check``)."""
from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np

from ..core import network
from ..core.khepera import SENSORS, WORLD_KEYS, World
from ..effects.base import Array
from ..recording import Recording

BASES = ('auto', 'model', 'observed')
MIN_SAMPLES = 40


class ProtocolError(ValueError):
    """The recording cannot be reproduced in the simulator; the message says why."""


def kind(rec: Recording) -> str:
    """'stationary' or 'closed_loop': the manifest's protocol, else whether turns are known."""
    declared = rec.manifest.get('protocol')
    if declared in ('stationary', 'closed_loop'):
        return str(declared)
    return 'closed_loop' if np.isfinite(rec.direction).any() else 'stationary'


def labels(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(values, return_inverse=True)`` of a label column that changes seldom (the
    lighting conditions): the labels of its stretches sorted, not every string."""
    if values.size == 0:
        return np.unique(values, return_inverse=True)
    start = np.flatnonzero(np.r_[True, values[1:] != values[:-1]])
    ordered, code = np.unique(values[start], return_inverse=True)
    return ordered, np.repeat(code.ravel(), np.diff(np.r_[start, values.size]))


def runs(rec: Recording) -> list[np.ndarray]:
    """Sample indices of each (episode, condition, heading) run, in step order."""
    heading = np.nan_to_num(np.round(rec.heading_deg, 1), nan=1e9)
    _, cond = labels(rec.condition)
    order = np.lexsort((rec.step, heading, cond, rec.episode))
    key = np.stack([rec.episode[order], cond[order], heading[order]], axis=1)
    edges = np.flatnonzero((np.diff(key, axis=0) != 0).any(axis=1)) + 1
    return np.split(order, edges) if order.size else []


def episodes(rec: Recording) -> list[np.ndarray]:
    """Sample indices of each episode in step order."""
    _, ep, order, _, _ = ordered(rec)
    return np.split(order, np.flatnonzero(np.diff(ep)) + 1)


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
        reasons.append(f'the recording has {rec.channels} channels, the light model {SENSORS}')
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


def genome_of(rec: Recording) -> Array:
    genome = rec.manifest.get('genome')
    if genome is None:
        raise ProtocolError('a closed-loop recording needs the controller genome in its '
                            'manifest (genome: [20 numbers]) to be reproduced')
    try:
        out: Array = network.check_genomes(genome)[0]
    except ValueError as exc:
        raise ProtocolError(f'manifest genome: {exc}') from None
    return out


def check(recordings: Sequence[Recording]) -> None:
    """Refuse input the diagnosis cannot make sense of: a ValueError of one line naming the
    recording and what is wrong (none given, too few samples, different channel layouts,
    no variation, a closed-loop recording without its genome)."""
    if not recordings:
        raise ValueError('the diagnosis needs at least one recording')
    for i, rec in enumerate(recordings):
        rec.check()
        if len(rec) < MIN_SAMPLES:
            raise ValueError(f'recording {name(rec, i)} has {len(rec)} samples; the '
                             f'diagnosis needs at least {MIN_SAMPLES}')
    if len({(r.channels, tuple(r.channels_used)) for r in recordings}) > 1:
        described = '; '.join(f'{name(r, i)}: {r.channels} channels, using '
                              f'{r.channels_used}' for i, r in enumerate(recordings))
        raise ValueError(f'the recordings disagree on their light channels ({described}); '
                         f'diagnose recordings of one robot together')
    for i, rec in enumerate(recordings):
        if kind(rec) == 'stationary':
            used = rec.readings[:, rec.channels_used]
            if not any(np.ptp(used[r], axis=0).max() > 0 for r in runs(rec)):
                raise ValueError(f'recording {name(rec, i)} has no variation: every used '
                                 f'channel is constant at every heading, so its noise cannot '
                                 f'be compared (a disconnected or stuck sensor?)')
        elif not calibrating(rec):     # a turn calibration has no genome
            genome_of(rec)


def name(rec: Recording, i: int) -> str:
    return str(rec.manifest.get('name', f'#{i + 1}'))


def calibrating(rec: Recording) -> bool:
    """Is ``rec`` a turn calibration (commands of the protocol, not of a genome)?"""
    return rec.manifest.get('calibration') == 'turns'


def ordered(rec: Recording) -> tuple[np.ndarray, ...]:
    """(episodes, episode index, sample order, steps, pair): the recording in episode and
    step order; ``pair``: the sample and the one before are consecutive steps of one."""
    episodes, ep = np.unique(rec.episode, return_inverse=True)
    order = np.lexsort((rec.step, ep))
    ep, steps = ep[order], rec.step[order]
    return episodes, ep, order, steps, consecutive(ep, steps)


def consecutive(ep: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Per sample (in episode and step order): is the one before the step before it?"""
    out: np.ndarray = np.r_[False, (ep[1:] == ep[:-1]) & (steps[1:] == steps[:-1] + 1)]
    return out
