"""``actuator_response``: the executed turn for each commanded size and direction.

A dead-band (static friction eats that many degrees of every turn), a gain beyond it,
different to the right and to the left, optionally a scale per commanded size (a table
over degrees), and scatter (a share of the turn made, and degrees per turn).  With
``knocks`` the task's heading knocks go through the same wheels.  The fit: executed
turns where they are measured (tracked headings, or the turn-calibration protocol) by
least squares; else the closed loop's turn statistics through the simulator.  A
response that is a plain scale defers to ``actuator_turn_error``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from scipy import stats as sps
from scipy.optimize import nnls

from .base import Array, Candidate, Effect, Evidence, Stage, Step, param
from .fitting import ALPHA, CLOSED_LOOP, golden, present

BANDS = np.round(np.arange(0.0, 8.0001, 0.1), 1)     # dead-bands tried, degrees
MIN_TURNS = 20                                         # measured turns a direct fit needs
FORM = 0.25           # share of the plain scale's objective the form must remove (closed loop)
GRID_BANDS, GRID_SIDES = (0.0, 2.0, 4.0, 6.0), (-0.3, 0.0, 0.3)    # the closed loop's start
GRID_GAINS = (0.9, 1.1, 1.3)          # times the plain scale: a dead-band needs more gain


@dataclass(frozen=True)
class ActuatorResponse(Effect):
    """A commanded turn of x degrees (positive to the right) turns sign(x) gain (1 +- a)
    scale(|x|) max(|x| - dead_band, 0) (1 + scatter N) + jitter N degrees (+ to the
    right); no turn is made of a zero command."""

    name: ClassVar[str] = 'actuator_response'
    stage: ClassVar[Stage] = Stage.ACTUATOR
    free: ClassVar[int] = 4
    summary: ClassVar[str] = 'the turn made differs in form: dead-band, sides, size, scatter'
    wheel_knocks: ClassVar[bool] = True
    dead_band: float = param(0.0, 'degrees of each turn the wheels do not make', low=0.0,
                             high=45.0)
    gain: float = param(1.0, 'turn made per commanded degree beyond the dead-band', low=0.0,
                        high=5.0)
    asymmetry: float = param(0.0, 'right turns gain (1 + a), left (1 - a)', low=-0.9,
                             high=0.9)
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
        out = np.sign(deg) * self.gain * (1 + np.sign(deg) * self.asymmetry) * \
            np.maximum(size - self.dead_band, 0.0)
        if self.sizes:
            out = out * np.interp(size, self.sizes, self.scales)
        result: Array = out
        return result

    def _made(self, deg: Array, z: Array | None) -> Array:
        out = self.mean(deg)
        if z is not None:
            out = out + (self.scatter * np.abs(out) * z[0] + self.jitter * z[1]) * (deg != 0)
        return out

    def start(self, robots: int, channels: int, rng: np.random.Generator) -> Step:
        random = bool(self.scatter or self.jitter)
        return lambda deg: self._made(deg, rng.standard_normal((2,) + np.shape(deg))
                                      if random else None)

    def over_time(self, level: Array, rng: np.random.Generator) -> Array:
        """Commanded turns (samples, 1, robots) in degrees, made."""
        if not (self.scatter or self.jitter):
            return self._made(level, None)
        z = rng.standard_normal((level.shape[0], 2) + level.shape[2:])
        return self._made(level, np.moveaxis(z, 1, 0)[:, :, None])

    @classmethod
    def fit(cls, evidence: Evidence) -> Candidate:
        if CLOSED_LOOP not in evidence.kinds:
            return Candidate(cls.name, None, 'no closed-loop or turn-calibration recording: '
                                             'record --protocol turns to measure the turns')
        turns = evidence.turns()
        turns = turns[np.isfinite(turns).all(axis=1) & (turns[:, 0] != 0)]
        if len(turns) >= MIN_TURNS:
            effect, plain = _direct(turns)
            how = f'{len(turns)} turns measured'
        else:
            effect, plain = _through_loop(evidence)
            how = 'the closed loop\'s turn statistics (no turns measured)'
        if plain:
            return Candidate(cls.name, None, f'{how}: a plain scale of the turn '
                                             f'(actuator_turn_error\'s case)')
        table = f', scale by size {dict(zip(effect.sizes, effect.scales))}' if effect.sizes \
            else ''
        return Candidate(cls.name, effect, f'{how}: dead-band {effect.dead_band:g} deg, gain '
                                           f'{effect.gain:g}, asymmetry {effect.asymmetry:g}'
                                           f'{table}, scatter {effect.scatter:g}, jitter '
                                           f'{effect.jitter:g} deg')


def _sides(c: Array, e: Array, w: Array, band: float) -> tuple[float, float, float]:
    """(right gain, left gain, weighted residual sum of squares) beyond ``band``."""
    out, rss = [], 0.0
    for side in (1.0, -1.0):
        at = np.sign(c) == side
        x = side * np.maximum(np.abs(c[at]) - band, 0.0)
        g = float((w[at] * x) @ e[at] / ((w[at] * x) @ x)) if x @ x > 0 else 1.0
        out.append(g)
        rss += float((w[at] * (e[at] - g * x) ** 2).sum())
    return out[0], out[1], rss


def _form(c: Array, e: Array, w: Array) -> tuple[ActuatorResponse, float]:
    """The dead-band and the two sides' gains by weighted least squares, and the RSS."""
    (right, left, rss), band = min(((_sides(c, e, w, b), b) for b in BANDS),
                                   key=lambda f: f[0][2])
    asym = float(np.clip((right - left) / (right + left), -0.9, 0.9)) if right + left > 0 \
        else 0.0
    return ActuatorResponse(float(band), round((right + left) / 2, 4), round(asym, 4)), rss


def _direct(turns: Array) -> tuple[ActuatorResponse, bool]:
    """Weighted least squares on measured turns (weights from the scatter of a first fit);
    ``plain`` when neither the dead-band and the sides nor a scale per size improve on a
    single scale (F tests at ``ALPHA``)."""
    c, e = turns[:, 0], turns[:, 1]
    n = len(c)
    effect, _ = _form(c, e, np.ones(n))
    scatter, jitter = _scatter(effect.mean(c), e - effect.mean(c))
    w = 1.0 / (scatter ** 2 * effect.mean(c) ** 2 + jitter ** 2 + 0.01)
    effect, rss = _form(c, e, w)
    scale = float((w * c) @ e / ((w * c) @ c))
    rss0 = float((w * (e - scale * c) ** 2).sum())
    made = effect.mean(c)
    sizes = np.unique(np.abs(c))
    ratio, p_size = [], 1.0
    if sizes.size >= 3:           # a scale per commanded size where it fits better
        rss_table = 0.0
        for size in sizes:
            g = np.abs(c) == size
            m = made[g]
            r = float((w[g] * m) @ e[g] / ((w[g] * m) @ m)) if m @ m > 0 else 1.0
            ratio.append(round(float(np.clip(r, 0.0, 5.0)), 4))
            rss_table += float((w[g] * (e[g] - r * m) ** 2).sum())
        dof = n - 3 - sizes.size
        if dof > 0 and rss_table > 0:
            p_size = float(sps.f.sf(((rss - rss_table) / sizes.size) / (rss_table / dof),
                                    sizes.size, dof))
    dof = max(n - 3, 1)
    p_form = float(sps.f.sf(((rss0 - rss) / 2) / (rss / dof), 2, dof)) if rss > 0 else 0.0
    table = (tuple(float(x) for x in sizes), tuple(ratio)) if p_size < ALPHA else ((), ())
    made = ActuatorResponse(effect.dead_band, effect.gain, effect.asymmetry, *table).mean(c)
    scatter, jitter = _scatter(made, e - made)
    effect = ActuatorResponse(effect.dead_band, effect.gain, effect.asymmetry, *table,
                              scatter, jitter)
    return effect, p_form >= ALPHA and p_size >= ALPHA


def _scatter(made: Array, residual: Array) -> tuple[float, float]:
    """(share, degrees): residual variance = share^2 made^2 + degrees^2, non-negative."""
    coef, _ = nnls(np.stack([made ** 2, np.ones_like(made)], axis=1), residual ** 2)
    return round(float(np.sqrt(coef[0])), 4), round(float(np.sqrt(coef[1])), 3)


def _through_loop(evidence: Evidence) -> tuple[ActuatorResponse, bool]:
    """Dead-band, asymmetry and gain on the closed loop's statistics (a grid, then
    golden-section search of each in turn); ``plain`` when the dead-band and the sides
    remove less than ``FORM`` of what the plain scale leaves."""
    kinds = present(evidence, (CLOSED_LOOP,))
    families = evidence.families() - evidence.families('closed_loop_noise')

    def objective(band: float, gain: float, asym: float) -> float:
        return evidence.objective([ActuatorResponse(round(band, 2), round(gain, 4),
                                                    round(asym, 4))], kinds, families)
    scale = golden(lambda g: objective(0.0, g, 0.0), 0.5, 1.6, 7)
    # the dead-band and the sides move the same statistics: a coarse grid of both first,
    # then each refined in turn
    band, gain, asym = min(((b, scale * g, a) for b in GRID_BANDS for g in GRID_GAINS
                            for a in GRID_SIDES), key=lambda p: objective(*p))
    for _ in range(2):
        band = golden(lambda b: objective(b, gain, asym), max(0.0, band - 1.5), band + 1.5, 5)
        asym = golden(lambda a: objective(band, gain, a), max(-0.9, asym - 0.15),
                      min(0.9, asym + 0.15), 5)
        gain = golden(lambda g: objective(band, g, asym), gain * 0.85, gain * 1.2, 5)
    plain = objective(band, gain, asym) >= (1 - FORM) * objective(0.0, scale, 0.0)
    return ActuatorResponse(round(band, 2), round(gain, 4), round(asym, 4)), plain
