"""``sensor_gain_offset``: each sensor's calibration differs from the light model's.

The fit: the sensors whose levels differ from the light model's (a chi-square over the
cells, Holm), each with the line mapping simulated levels onto real ones; where the
levels also move together over time, the steady levels (each run divided by its shared
factor) are fitted instead.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats as sps

from ..core.khepera import DARK
from .base import Array, Candidate, Effect, Evidence, Stage, param, rows
from .fitting import by_sensor, names, significant


@dataclass(frozen=True)
class SensorGainOffset(Effect, name='sensor_gain_offset', stage=Stage.LIGHT, free=4,
                       summary='per-sensor calibration differences in the light response'):
    """reading = anchor - gain * (anchor - ideal) + offset, per sensor."""

    sensors: tuple[int, ...] = param((), 'sensors whose calibration differs', 'sensors')
    gains: tuple[float, ...] = param((), 'gain about the anchor, per sensor', 'floats',
                                     per_sensor=True)
    offsets: tuple[float, ...] = param((), 'offset in readings, per sensor', 'floats',
                                       per_sensor=True)
    anchor: float = param(DARK, 'reading the gain turns about (the dark end)')

    def act(self, level: Array, rng: np.random.Generator) -> Array:
        located = rows(self.sensors, level.shape[1])
        g, o = np.ones((level.shape[1], 1)), np.zeros((level.shape[1], 1))
        g[located, 0], o[located, 0] = self.gains, self.offsets
        return self.anchor - g * (self.anchor - level) + o

    @classmethod
    def fit(cls, evidence: Evidence) -> Candidate:
        levels = evidence.rows('level')
        if not levels or evidence.observed_base:
            return cls.nothing('no levels from the light model to compare')
        change = evidence.shared_change()
        moved = bool(change and change['significant'])
        if moved and change:          # what a shared change over time leaves is the calibration
            levels = evidence.steady_rows(levels, change)
        cells = by_sensor(levels)
        located = significant(cells, [sps.chi2.sf(sum(r.z * r.z for r in v), len(v))
                                      for v in cells.values()])
        if not located:
            return cls.nothing('no sensor\'s levels differ significantly' + (
                ' beyond a shared change over time' if moved else ''))
        gains, offsets = [], []
        for s in located:
            real, sim = (np.array(v) for v in zip(*[(r.real, r.sim) for r in cells[s]]))
            g, a = np.polyfit(sim, real, 1) if np.ptp(sim) > 1 else (1.0, real.mean() - sim.mean())
            gains.append(round(float(g), 4))
            offsets.append(round(float(a - DARK * (1 - g)), 2))
        return Candidate(cls.name, cls(tuple(located), tuple(gains), tuple(offsets), DARK),
                         f'levels of {names(located)} off the light model')
