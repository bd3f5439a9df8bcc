"""Small recordings from the core, for the tests of the readers, writers and analyses."""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from .. import recording
from ..core.noise import NoiseModel
from ..core.task import Episodes, Task, Trace


def manifest(conditions: Sequence[str] = ('bright',), **extra: Any) -> dict[str, Any]:
    """A simulator recording's manifest with these conditions (lamp at 5 mm) and ``extra``."""
    return {'format': recording.FORMAT, 'source': 'simulator', 'sample_period_s': 1.0,
            'conditions': {c: {'lamp_distance_mm': 5.0} for c in conditions}, **extra}


def _still(env: Episodes, seed: int, headings: Sequence[float]) -> Trace:
    """The trace of robots at ``headings`` that never turn, until the episodes end."""
    readings, rows = env.reset(seed, len(headings), bearing_deg=headings), []
    zeros = np.zeros(len(headings), np.int32)
    while readings is not None:
        rows.append((env.bearing_deg, readings.copy(), zeros + 1, zeros))
        readings = env.step(zeros + 1, zeros)
    return Trace(*(np.stack(c) for c in zip(*rows)))


def stationary(noise: NoiseModel = NoiseModel(), headings: Sequence[float] = (0.0, 30.0),
               steps: int = 20, seed: int = 1, condition: str = 'bright',
               first_episode: int = 0) -> recording.Recording:
    """Readings of robots that never turn: what section 2 records, from the core."""
    env = Episodes(noise=noise, task=Task(steps=steps, perturbation_deg=0))
    return recording.from_trace(_still(env, seed, headings), condition,
                                manifest([condition], noise={'model': noise.model}),
                                first_episode, stationary=True)


def sample_recording() -> recording.Recording:
    """Two still robots for six steps, with the plainest manifest: the valid file the
    property and disk tests start from."""
    env = Episodes(task=Task(steps=6, perturbation_deg=0))
    return recording.from_trace(_still(env, 5, [0.0, 30.0]), 'bright', manifest(),
                                stationary=True)
