"""``actuator_response``: the turn made for each commanded size and direction.

A dead-band (static friction eats that many degrees of every turn), a gain beyond it, its
own to each side, optionally a scale per commanded size, and scatter.  The fit: measured
turns (tracked headings, or the turn-calibration protocol) by weighted least squares.
Without them it is not fitted (the closed loop's statistics alone confound its form with
the noise; the turn error there is ``actuator_turn_error``'s), nor where a plain scale
fits as well.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np
from scipy import stats as sps
from scipy.optimize import nnls

from .base import Array, Candidate, Effect, Evidence, Stage, param
from .fitting import ALPHA, CLOSED_LOOP

BANDS = np.round(np.arange(0.0, 8.0001, 0.1), 1)     # dead-bands tried, degrees
MIN_TURNS = 20                                         # measured turns a direct fit needs
TINY = 1e-9           # weighted squared residual per turn below which a fit gains nothing


@dataclass(frozen=True)
class ActuatorResponse(Effect, name='actuator_response', stage=Stage.ACTUATOR, free=4,
                       plain='actuator_turn_error',
                       summary='the turn made differs in form: dead-band, sides, size, scatter'):
    """A commanded turn of x degrees (positive to the right) turns sign(x) gain (1 +- a)
    scale(|x|) max(|x| - dead_band, 0) (1 + scatter N) + jitter N degrees (+ to the
    right); no turn is made of a zero command."""

    wheel_knocks: ClassVar[bool] = True
    dead_band: float = param(0.0, 'degrees of each turn the wheels do not make', low=0.0,
                             high=45.0)
    gain: float = param(1.0, 'turn made per commanded degree beyond the dead-band', low=0.0,
                        high=5.0)
    asymmetry: float = param(0.0, 'right turns gain (1 + a), left (1 - a)', low=-0.9, high=0.9)
    sizes: tuple[float, ...] = param((), 'commanded sizes of the scale table, degrees',
                                     'floats', above=0.0, ascending=True)
    scales: tuple[float, ...] = param((), 'scale at each size (constant beyond)', 'floats',
                                      low=0.0, high=5.0)
    scatter: float = param(0.0, 'sd of the turn made, a share of it', low=0.0, high=2.0)
    jitter: float = param(0.0, 'sd of each turn made, degrees', low=0.0, high=45.0)
    knocks: bool = param(True, 'the task\'s heading knocks go through the same wheels')

    def inconsistency(self) -> str:
        return '' if len(self.sizes) == len(self.scales) else 'needs one scale per size'

    def mean(self, deg: Array) -> Array:
        """The turn made of commanded turns ``deg`` without scatter."""
        size = np.abs(deg)
        out: Array = np.sign(deg) * self.gain * (1 + np.sign(deg) * self.asymmetry) * \
            np.maximum(size - self.dead_band, 0.0)
        return out * np.interp(size, self.sizes, self.scales) if self.sizes else out

    def act(self, level: Array, rng: np.random.Generator) -> Array:
        out = self.mean(level)
        if self.scatter or self.jitter:
            z = rng.standard_normal((level.shape[0], 2) + level.shape[1:])
            out = out + (self.scatter * np.abs(out) * z[:, 0] + self.jitter * z[:, 1]) \
                * (level != 0)
        return out

    @classmethod
    def fit(cls, evidence: Evidence) -> Candidate:
        if CLOSED_LOOP not in evidence.kinds:
            return cls.nothing('no closed-loop or turn-calibration recording: record '
                               '--protocol turns to measure the turns')
        turns = evidence.turns()
        turns = turns[np.isfinite(turns).all(axis=1) & (turns[:, 0] != 0)]
        if len(turns) < MIN_TURNS:
            return cls.nothing(f'{len(turns)} turns measured (needs {MIN_TURNS}): record '
                               '--protocol turns, or a robot that reports its heading; the '
                               'closed loop\'s turn error is actuator_turn_error\'s')
        effect, plain = _direct(turns)
        how = f'{len(turns)} turns measured'
        if plain:
            return cls.nothing(f'{how}: a plain scale of the turn (actuator_turn_error\'s case)')
        table = f', scale by size {dict(zip(effect.sizes, effect.scales))}' if effect.sizes else ''
        return Candidate(cls.name, effect, f'{how}: dead-band {effect.dead_band:g} deg, gain '
                         f'{effect.gain:g}, asymmetry {effect.asymmetry:g}{table}, scatter '
                         f'{effect.scatter:g}, jitter {effect.jitter:g} deg')


def _gain(x: Array, y: Array, w: Array) -> tuple[float, float]:
    """The weighted least-squares scale of ``x`` to ``y`` (1 for no ``x``) and its RSS."""
    g = float((w * x) @ y / ((w * x) @ x)) if x @ x > 0 else 1.0
    return g, float((w * (y - g * x) ** 2).sum())


def _form(c: Array, e: Array, w: Array) -> tuple[ActuatorResponse, float]:
    """The dead-band and the two sides' gains by weighted least squares, and the RSS."""
    def sides(band: float) -> tuple[float, float, float]:
        fits = [_gain(side * np.maximum(np.abs(c[at]) - band, 0.0), e[at], w[at])
                for side, at in ((1.0, c > 0), (-1.0, c < 0))]
        return fits[0][0], fits[1][0], fits[0][1] + fits[1][1]
    (right, left, rss), band = min(((sides(b), b) for b in BANDS), key=lambda f: f[0][2])
    asym = float(np.clip((right - left) / (right + left), -0.9, 0.9)) if right + left > 0 else 0.0
    return ActuatorResponse(float(band), round((right + left) / 2, 4), round(asym, 4)), rss


def _direct(turns: Array) -> tuple[ActuatorResponse, bool]:
    """Weighted least squares on measured turns (weights from the scatter of a first fit);
    ``plain`` when neither the dead-band and the sides nor a scale per size improve on a
    single scale (F tests at ``ALPHA``)."""
    c, e = turns[:, 0], turns[:, 1]
    n = len(c)
    effect, _ = _form(c, e, np.ones(n))
    scatter, jitter = _scatter(effect, c, e)
    w = 1.0 / (scatter ** 2 * effect.mean(c) ** 2 + jitter ** 2 + 0.01)
    effect, rss = _form(c, e, w)
    rss0 = _gain(c, e, w)[1]
    made = effect.mean(c)
    sizes = np.unique(np.abs(c))
    p_size = 1.0
    if sizes.size >= 3:           # a scale per commanded size where it fits better
        fits = [_gain(made[g], e[g], w[g]) for g in (np.abs(c) == size for size in sizes)]
        rss_table = sum(rss_size for _, rss_size in fits)
        dof = n - 3 - sizes.size
        if dof > 0 and rss - rss_table > TINY * n:
            f = ((rss - rss_table) / sizes.size) / max(rss_table / dof, TINY)
            p_size = float(sps.f.sf(f, sizes.size, dof))
        if p_size < ALPHA:
            effect = replace(effect, sizes=tuple(float(x) for x in sizes),
                             scales=tuple(round(float(np.clip(r, 0.0, 5.0)), 4) for r, _ in fits))
    dof = max(n - 3, 1)
    p_form = float(sps.f.sf(((rss0 - rss) / 2) / max(rss / dof, TINY), 2, dof)) \
        if rss0 - rss > TINY * n else 1.0
    scatter, jitter = _scatter(effect, c, e)
    return replace(effect, scatter=scatter, jitter=jitter), p_form >= ALPHA and p_size >= ALPHA


def _scatter(effect: ActuatorResponse, c: Array, e: Array) -> tuple[float, float]:
    """(share, degrees) of the turns ``e`` made about the effect's of commands ``c``: residual
    variance = share^2 made^2 + degrees^2, non-negative."""
    made = effect.mean(c)
    coef, _ = nnls(np.stack([made ** 2, np.ones_like(made)], axis=1), (e - made) ** 2)
    return round(float(np.sqrt(coef[0])), 4), round(float(np.sqrt(coef[1])), 3)
