"""``saturation_quantization``: the sensor's converter.

Readings held at a floor or a ceiling, on a lattice coarser than the model's, or lost
(replaced by a dropout value).  The fit reads the converter's evidence (the limits the
real readings pile up at, each sensor's lattice, the dropouts) and lets the simulator
choose among the combinations that evidence allows.
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import product
from typing import Any

import numpy as np

from ..core.khepera import DARK
from .base import Array, Candidate, Effect, Evidence, Stage, param, replaced, rows
from .fitting import STATIONARY, names, on_grid, present


@dataclass(frozen=True)
class SaturationQuantization(
        Effect, name='saturation_quantization', stage=Stage.READING, free=3,
        summary='readings clipped at a floor or ceiling, on a coarser lattice, or dropping out'):
    sensors: tuple[int, ...] = param((), 'sensors of the converter', 'sensors')
    low: float = param(0.0, 'floor: no reading lies below')
    high: float = param(DARK, 'ceiling: no reading lies above')
    step: float = param(1.0, 'lattice step', above=0.0)
    dropout: float = param(0.0, 'chance that a reading is lost', low=0.0, high=0.999999)
    dropout_value: float = param(0.0, 'what a lost reading reads')
    origin: float = param(0.0, 'the lattice is origin + k * step')

    def inconsistency(self) -> str:
        return 'low must be below high' if self.low >= self.high else ''

    def act(self, level: Array, rng: np.random.Generator) -> Array:
        located = rows(self.sensors, level.shape[1])
        lattice = np.round((level[:, located] - self.origin) / self.step) * self.step + self.origin
        read = np.clip(lattice, self.low, self.high)
        if self.dropout > 0:
            read = np.where(rng.random(read.shape) < self.dropout, self.dropout_value, read)
        return replaced(level, located, read)

    @classmethod
    def fit(cls, evidence: Evidence) -> Candidate:
        found: dict[str, Any] = evidence.converter()
        low, high = (_strongest(found['limits'], end) for end in (0, 1))
        grid, lost, top = found['lattices'], found['dropouts'], found['top']
        if not (low or high or grid or lost):
            return cls.nothing('no readings held at a limit, no coarse value grid and no '
                               'dropouts')
        drop: dict[str, float] = {}
        if lost:
            values = [v for v, _ in lost.values()]
            drop = {'dropout': round(float(np.median([r for _, r in lost.values()])), 5),
                    'dropout_value': max(set(values), key=values.count)}
        lattices = list(grid.values())
        step, origin = max(set(lattices), key=lattices.count) if lattices else (1, 0)
        # one effect rounds only the sensors whose lattice is the chosen one or a coarser part
        gridded = {s for s, (k, o) in grid.items()
                   if on_grid(np.array([o, o + k]), step, origin) == 1.0}
        options = []
        # with dropouts, a grid is tried without its lattice too: only what is needed
        for lo, hi, use_grid in product([None, low] if low else [None],
                                        [None, high] if high else [None],
                                        [False, True] if grid and lost else [bool(grid)]):
            sensors = (gridded if use_grid else set()) | set(lost) | \
                set(lo['sensors'] if lo else ()) | set(hi['sensors'] if hi else ())
            low_value, high_value = lo['value'] if lo else 0.0, hi['value'] if hi else top
            if sensors and low_value < high_value:
                options.append(cls(tuple(sorted(sensors)), low_value, high_value,
                                   float(step) if use_grid else 1.0,
                                   origin=float(origin) if use_grid else 0.0, **drop))
        kinds = present(evidence, (STATIONARY,))
        effect: Effect = min(options, key=lambda e: evidence.objective([e], kinds, limits=True))
        if lost:
            effect = evidence.rescaled_dropout(effect, sorted(lost))
        assert isinstance(effect, cls)
        what = [w for w, shown in ((f'clipped below at {effect.low:g}', effect.low > 0),
                                   (f'clipped above at {effect.high:g}', effect.high < top),
                                   ('on a grid', effect.step > 1),
                                   (f'dropping out to {effect.dropout_value:g} at rate '
                                    f'{effect.dropout:.2%}', effect.dropout > 0)) if shown]
        return Candidate(cls.name, effect, f'{names(effect.sensors)} {" and ".join(what)}')


def _strongest(found: list[dict[str, Any]], end: int) -> dict[str, Any] | None:
    """The limit at ``end`` (0 floor, 1 ceiling) holding the most readings."""
    mine = [f for f in found if f['end'] == end]
    return max(mine, key=lambda f: f['share'] * len(f['sensors'])) if mine else None
