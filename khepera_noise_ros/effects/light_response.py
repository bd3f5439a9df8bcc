"""``light_response``: each sensor's light over bearing is the robot's, not the model's.

A table per lighting condition (as Webots' ``lookupTable``): the robot's level at knot
bearings, interpolated round the circle (Akima's local cubic from four knots on, linear
below), replaces the world's response of the sensors it names (``between='model'``: the
world's response plus the difference interpolated linearly).  The fit: the real levels at
the recorded headings, on the sensors whose levels no line through the model's explains,
where a sweep gives bearings enough for a shape (else a shape would be a guess).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.interpolate import Akima1DInterpolator

from ..core.khepera import DARK, TENTHS
from .base import Array, Candidate, Effect, Evidence, Row, Stage, param, rows
from .fitting import by_sensor, line_p, names, significant

SPARSE = 12           # fewer bearings than this round the circle leave the shape a guess


@dataclass(frozen=True)
class LightResponse(Effect, name='light_response', stage=Stage.WORLD, free=5,
                    summary="each sensor's light over bearing differs in shape from the model's"):
    """``levels[c][s][k]``: sensor ``sensors[s]``'s light at bearing ``bearings[k]`` in the
    condition of lamp distance ``lamps[c]`` and ambient ``ambients[c]``; the world's
    table is kept in conditions it does not list."""

    sensors: tuple[int, ...] = param((0,), 'sensors whose light response is tabled', 'sensors')
    bearings: tuple[float, ...] = param((0.0,), 'knot bearings, degrees', 'floats',
                                        low=-180.0, high=180.0, ascending=True)
    lamps: tuple[float, ...] = param((5.0,), 'lamp distance of each condition, mm', 'floats',
                                     low=0.0)
    ambients: tuple[float, ...] = param((500.0,), 'ambient of each condition', 'floats',
                                        low=0.0, high=DARK)
    levels: tuple[float, ...] = param((500.0,), 'level per condition, sensor and knot',
                                      'floats', low=-DARK, high=2 * DARK)
    between: str = param('level', "between knots: the table's levels, or the world's "
                         'response plus the difference', choices=('level', 'model'))

    def inconsistency(self) -> str:
        c, s, k = len(self.lamps), len(self.sensors), len(self.bearings)
        if not s or not k or not c or len(self.ambients) != c:
            return 'needs sensors, bearings and as many lamps as ambients'
        if len(set(np.round(np.mod(self.bearings, 360.0), 6))) < k:
            return 'bearings repeat a direction'
        if len(self.levels) != c * s * k:
            return f'levels needs {c} x {s} x {k} values'
        return ''

    def act(self, level: Array, rng: np.random.Generator) -> Array:
        """Nothing per sample: the effect acts where the world's table is made."""
        out: Array = level.copy()
        return out

    def table(self, table: Array, world: Any) -> Array:
        out: Array = np.array(table, np.float64)
        listed = [c for c, (lamp, ambient) in enumerate(zip(self.lamps, self.ambients)) if
                  np.isclose(lamp, world.lamp_distance_mm) and np.isclose(ambient, world.ambient)]
        if not listed:
            return out
        grid = np.arange(table.shape[1]) * (360.0 / table.shape[1])
        levels = np.reshape(self.levels, (len(self.lamps), len(self.sensors), -1))[listed[0]]
        knots = np.asarray(self.bearings)
        at = np.rint(np.mod(knots, 360.0) * table.shape[1] / 360.0).astype(int) % table.shape[1]
        for i, s in enumerate(rows(self.sensors, table.shape[0])):
            if self.between == 'level':
                out[s] = around(grid, knots, levels[i])
            else:
                out[s] += np.interp(grid, np.mod(knots, 360.0), levels[i] - out[s, at],
                                    period=360.0)
        return out

    @classmethod
    def fit(cls, evidence: Evidence) -> Candidate:
        levels = evidence.rows('level')
        if not levels or evidence.observed_base:
            return cls.nothing('no levels from the light model to compare')
        # the levels as read (a shape no line explains also moves the runs' shared factors,
        # so they are not divided out as a change over time)
        located = _misshapen(levels, evidence.rows('spread'))
        if not located:
            return cls.nothing('every sensor\'s levels follow the light model up to a '
                               'calibration and its noise')
        worlds = evidence.worlds()
        cells = {(str(r.key.condition), b, r.key.sensors[0]): r for r in levels
                 if (b := _bearing(r)) is not None and r.key.condition in worlds}
        conditions = sorted({c for c, _, _ in cells})
        bearings = np.array(sorted({b for _, b, _ in cells}))
        seen = {c: sorted({b for cc, b, _ in cells if cc == c}) for c in conditions}
        stock = {c: np.asarray(worlds[c].light_table(rounded=False), np.float64)
                 for c in conditions}
        # a shape needs bearings enough wherever the lamp lights some sensor differently
        sparse = [c for c in conditions if len(seen[c]) < SPARSE
                  and np.ptp(stock[c][located], axis=1).max() > 1.0]
        if sparse:          # a shape is not guessed: the levels are a calibration's to fit
            text = '; '.join(f'{c}: {len(seen[c])}' for c in sparse)
            return cls.nothing(f'levels of {names(located)} differ in shape from the light '
                               f'model, but the bearings are too few for a shape (needs '
                               f'{SPARSE}; {text}): record --protocol sweep')
        values: list[float] = []
        for cond in conditions:
            for s in located:       # the model's light corrected by what the robot read
                mine = sorted((h, float(stock[cond][s, int(round(h * 10)) % TENTHS]) +
                               r.real - r.sim) for (c, h, k), r in cells.items()
                              if c == cond and k == s)
                knots, v = np.array(mine).T
                values += [round(float(x), 2) for x in around(bearings, knots, v)]
        effect = cls(tuple(located), tuple(float(b) for b in bearings),
                     tuple(float(worlds[c].lamp_distance_mm) for c in conditions),
                     tuple(float(worlds[c].ambient) for c in conditions), tuple(values))
        text = '; '.join(f'{c}: ' + ', '.join(f'{b:g}' for b in seen[c]) for c in conditions)
        return Candidate(cls.name, effect, f'levels of {names(located)} differ in shape from '
                         f'the light model; bearings seen (deg) {text}')


def around(x: Array, knots: Array, values: Array) -> Array:
    """``values`` at bearings ``knots`` (degrees) interpolated at ``x`` round the circle."""
    order = np.argsort(np.mod(knots, 360.0))
    k, v = np.mod(knots, 360.0)[order], np.asarray(values, np.float64)[order]
    if k.size < 4:
        return np.interp(np.mod(x, 360.0), k, v, period=360.0)
    curve = Akima1DInterpolator(np.r_[k[-3:] - 360.0, k, k[:3] + 360.0], np.r_[v[-3:], v, v[:3]])
    return np.asarray(curve(np.mod(x, 360.0)), np.float64)


def _bearing(r: Row) -> float | None:
    part = str(r.key.part or '')
    if not part.startswith('heading '):
        return None
    return (float(part.split()[1]) + 180.0) % 360.0 - 180.0


def _misshapen(levels: list[Row], spreads: list[Row]) -> list[int]:
    """Sensors whose levels stay off after the best line through the model's levels (a
    gain and offset): chi-square of the line's residuals, Holm, and by more than the
    sensor's own noise (the median spread of its cells: a controller cannot tell a smaller
    misfit from noise, and noise clipped at a limit moves a mean that much).  A level's
    error is at least its cell's spread times the median ratio of the two (short runs let
    the bootstrap understate some cells' errors)."""
    by_key = {r.key: r.real for r in spreads}
    spread = {r.key: by_key.get(r.key._replace(family='spread'), 0.0) for r in levels}
    ratio = [r.se / spread[r.key] for r in levels if spread[r.key] > 0]
    typical = float(np.median(ratio)) if ratio else 0.0
    cells, p, small = by_sensor(levels), [], set()
    for s, mine in cells.items():
        noise = float(np.median([spread[r.key] for r in mine]))
        real, sim, se = (np.array(v, np.float64) for v in zip(*[(
            r.real, r.sim, max(r.se, 0.3, typical * spread[r.key])) for r in mine]))
        if real.size < 3:
            p.append(1.0)
            continue
        line, chance = line_p(real, sim, se)
        p.append(chance)
        if float(np.sqrt(np.mean((real - line) ** 2))) < noise:
            small.add(s)
    return [s for s in significant(cells, p) if s not in small]
