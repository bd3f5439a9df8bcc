"""``intensity_dependent_noise``: noise whose size follows a law of the light level.

sd(r) = constant + strength * u * (u / scale) ** exponent with u = r ('dark': the noise
grows with darkness, the Khepera's 525 end, as a room's flicker) or u = scale - r; one
draw for all the sensors if ``shared``.  The fit: on the sensors whose fast noise is
shared beyond the simulator's (one shared draw), else on those with extra spread (a draw
each), the laws that fit the cells' excess variance best (non-negative least squares on
the sd over a grid of directions and exponents), then judged by the simulator.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.optimize import nnls

from ..core.khepera import DARK
from .base import Array, Candidate, Effect, Evidence, Stage, columns, held, param, replaced
from .correlated_noise import groups_of
from .fitting import Z_DETECT, names, refine

EXPONENTS = (-0.5, 0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0)
DIRECTIONS = ('dark', 'bright')
SPREADS = ('spread', 'loop_still_spread', 'loop_residual_spread', 'loop_change_spread')


@dataclass(frozen=True)
class IntensityDependentNoise(
        Effect, name='intensity_dependent_noise', stage=Stage.LIGHT, free=2,
        summary='noise amplitude or correlation that changes with the light level'):
    sensors: tuple[int, ...] = param((), 'sensors with the extra noise', 'sensors')
    strength: float = param(0.03, 'size of the law (sd per reading of u)', low=0.0)
    exponent: float = param(1.0, 'exponent of the law', low=-1.0)
    scale: float = param(DARK, 'reading the law is scaled to', above=0.0)
    constant: float = param(0.0, 'sd in readings at any level', low=0.0)
    direction: str = param('dark', "'dark': grows with darkness; 'bright': with light",
                           choices=DIRECTIONS)
    shared: bool = param(True, 'one draw for all the sensors (else one each)')

    def amplitude(self, level: Array) -> Array:
        return self.constant + self.strength * shape(level, self.direction, self.exponent,
                                                     self.scale)

    def act(self, level: Array, rng: np.random.Generator) -> Array:
        cols = columns(self.sensors, level.shape[1])
        width = 1 if self.shared else len(self.sensors)
        z = rng.standard_normal((level.shape[0], width, level.shape[2]))
        return replaced(level, cols, level[:, cols] + z * held(self.amplitude, level[:, cols]))

    @classmethod
    def fit(cls, evidence: Evidence) -> Candidate:
        z = evidence.group_evidence('fast')
        found = groups_of(evidence, z)
        shared = bool(found)
        if found:
            best = max(found, key=lambda g: z[np.ix_(g, g)].sum())
            sensors = tuple(evidence.channels[i] for i in best)
        else:
            sensors = tuple(sorted({r.key.sensors[0] for f in SPREADS for r in evidence.rows(f)
                                    if r.z > Z_DETECT}))
        if not sensors:
            return cls.nothing('no extra spread or shared noise to explain')
        options = [cls(sensors, round(k, 6), e, DARK, round(c0, 4), d, shared)
                   for d, e, c0, k, _ in laws(evidence.spread_cells(sensors))]
        options = [o for o in options if o.strength > 0 or o.constant > 0]
        # a constant part is poorly fixed by the unweighted fit (the darkest cells dominate;
        # other effects' transients add to them): the simulator also judges each law without
        options += [dataclasses.replace(o, constant=0.0) for o in options
                    if o.constant > 0 and o.strength > 0]
        if not options:
            return cls.nothing('extra spread fits no spread law')
        effect = min(options, key=lambda e: evidence.objective([e]))
        if effect.strength > 0:
            chosen = effect
            effect = refine(evidence, lambda s: dataclasses.replace(chosen, strength=s),
                            effect.strength, evaluations=5)
        u, grows = ('r', 'darkness') if effect.direction == 'dark' else ('(525 - r)', 'brightness')
        kind = 'one shared draw' if shared else 'a draw per sensor'
        return Candidate(cls.name, effect, f'extra spread on {names(sensors)}: sd = '
                         f'{effect.constant:.3g} + {effect.strength:.3g} * {u} * ({u} / 525)^'
                         f'{effect.exponent:g} (grows with {grows}), {kind}')


def shape(level: Array | float, direction: str, exponent: float, scale: float = DARK) -> Array:
    """u * (u / scale) ** exponent, u the distance from the quiet end; 0 where u is 0."""
    r = np.clip(np.asarray(level, np.float64), 0.0, scale)
    u = r if direction == 'dark' else scale - r
    with np.errstate(divide='ignore', invalid='ignore'):
        out = u * (u / scale) ** exponent
    return np.where(u > 0, np.nan_to_num(out, nan=0.0, posinf=0.0), 0.0)


def laws(cells: Sequence[tuple[float, float]]) -> list[tuple[str, float, float, float, float]]:
    """The three laws (direction, exponent, constant, strength, residual) that fit the
    cells [(level, excess variance)] best."""
    if not cells:
        return []
    level, variance = np.array(cells, np.float64).T
    sd = np.sqrt(np.clip(variance, 0.0, None))
    out = []
    for direction in DIRECTIONS:
        for exponent in EXPONENTS:
            x = np.stack([np.ones_like(level), shape(level, direction, exponent)], axis=1)
            if not np.isfinite(x).all() or x[:, 1].max() <= 0:
                continue
            norm = x.max(axis=0)
            coef, residual = nnls(x / norm, sd)
            coef = coef / norm
            out.append((direction, exponent, float(coef[0]), float(coef[1]), float(residual)))
    return sorted(out, key=lambda t: t[4])[:3]
