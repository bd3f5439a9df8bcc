"""``temporal_drift``: a slow wander of the sensors' gain, shared or each sensor's own.

The fit: extra autocorrelation of the residuals (or of each sensor's own part, which
noise shared by all sensors cannot hide), level offsets no fixed calibration makes, or
levels moving together from run to run (a shared change).  An own wander also moves the
shared factor a little: where both show, both are fitted and the simulator chooses.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats as sps
from scipy.optimize import minimize

from .base import (Array, Candidate, Effect, Evidence, Row, Stage, Step, ar1, columns, param,
                   replaced, rows)
from .fitting import Z_DETECT, by_condition, by_sensor, line_p, names, significant

MIN_TIME_CONSTANT = 0.5  # samples; below this a drift is white noise, not a drift
# Nelder-Mead objectives: 16, or 10 inside the box the own wanders bound (there the later
# steps gained less than the objective's noise between simulator seeds)
EVALUATIONS = (16, 10)


@dataclass(frozen=True)
class TemporalDrift(Effect, name='temporal_drift', stage=Stage.LIGHT, free=3,
                    summary='slow, autocorrelated change over time, per sensor or shared'):
    """AR(1) wander of the gain: sd ``sd`` (a fraction), correlation time ``time_constant``
    samples, one wander for all ``sensors`` if ``shared``."""

    sensors: tuple[int, ...] = param((), 'sensors that wander', 'sensors')
    sd: float = param(0.01, 'sd of the wander, a fraction of the level', low=0.0)
    time_constant: float = param(30.0, 'correlation time, samples', above=0.0)
    shared: bool = param(True, 'one wander for all the sensors (else one each)')

    def start(self, robots: int, channels: int, rng: np.random.Generator) -> Step:
        located = rows(self.sensors, channels)
        a = math.exp(-1.0 / self.time_constant)
        state = self.sd * rng.standard_normal((1 if self.shared else len(located), robots))

        def step(level: Array) -> Array:
            nonlocal state
            out = replaced(level, located, level[located] * (1.0 + state))
            state = a * state + math.sqrt(1 - a * a) * self.sd * rng.standard_normal(state.shape)
            return out
        return step

    def over_time(self, level: Array, rng: np.random.Generator) -> Array:
        cols = columns(self.sensors, level.shape[1])
        a = math.exp(-1.0 / self.time_constant)
        z = rng.standard_normal((level.shape[0], 1 if self.shared else len(self.sensors),
                                 level.shape[2]))
        z[0] *= self.sd
        z[1:] *= math.sqrt(1 - a * a) * self.sd
        return replaced(level, cols, level[:, cols] * (1.0 + ar1(z, a)))

    @classmethod
    def fit(cls, evidence: Evidence) -> Candidate:
        acf = evidence.rows('autocorrelation') or evidence.rows('loop_residual_autocorrelation')
        own = evidence.own_wander()
        located = tuple(sorted(set(_combined_excess(acf)) |
                               set(_unexplained_levels(evidence.rows('level'))) | set(own)))
        change = evidence.shared_change()
        moved = bool(change and change['significant'])
        if not located and not moved:
            return cls.nothing('no extra autocorrelation over time and no level offsets '
                               'beyond a fixed calibration')
        searches = []
        if moved:
            searches.append(_search(evidence, acf, own, tuple(evidence.channels), change))
        if located and (own or not moved):
            searches.append(_search(evidence, acf, own, located, None))
        effect, _, shared_change = min(searches, key=lambda s: s[1])
        kind = 'one shared wander' if effect.shared else 'a wander per sensor'
        how = f'; levels move together over time (sd {change["sd"]:.1%})' \
            if shared_change and change else ''
        return Candidate(cls.name, effect, f'slow wander on {names(effect.sensors)} ({kind}){how}')


def _search(evidence: Evidence, acf: list[Row], own: dict[int, dict[str, Any]],
            sensors: tuple[int, ...],
            change: dict[str, Any] | None) -> tuple[TemporalDrift, float, bool]:
    """(effect, objective, whether it is the shared change's) of one search: a
    change shared by all sensors from the run-to-run factors (``change``), or a wander on
    ``sensors`` bounded by their own wanders' size and time."""
    moved = change is not None
    idx = [evidence.channels.index(s) for s in sensors]
    slow = evidence.group_evidence('slow')[np.ix_(idx, idx)]
    shared = moved or len(idx) > 1 and slow[~np.eye(len(idx), dtype=bool)].mean() > Z_DETECT
    rho = {lag: float(np.mean([r.real - r.sim for r in acf
                               if r.key.sensors[0] in sensors and r.key.part == f'lag {lag}']
                              or [np.nan])) for lag in (1, 3)}
    if not np.isfinite(rho[1]):
        rho[1] = 0.0
    if not np.isfinite(rho[3]):          # closed loop: lag 1 only; as an AR(1) would
        rho[3] = max(rho[1], 0.0) ** 3
    a = float(np.clip((max(rho[3], 1e-3) / max(rho[1], 1e-3)) ** 0.5, 0.3, 0.995))
    if own:                              # the own parts' excess, lag 10 against lag 1
        r1, r10 = (float(np.median([v['acf'][lag] for v in own.values()])) for lag in (1, 10))
        a = float(np.clip((max(r10, 1e-3) / max(r1, 1e-3)) ** (1 / 9), 0.3, 0.995))
    tau0 = -1.0 / math.log(a)
    spread, level = by_condition(evidence.rows('spread')), by_condition(evidence.rows('level'))
    ratio = [spread[cond][s][0] / level[cond][s][1] for cond in spread for s in sensors
             if level.get(cond, {}).get(s, (0, 0))[1] > 0]
    sd0 = float(np.sqrt(max(rho[1], 0.01)) * np.mean(ratio)) if ratio else 0.01
    if own:
        sd0 = float(np.median([v['sd'] for v in own.values()])) or sd0
    if change is not None:       # from the shared factors' spread, slow over the runs
        sd0 = max(sd0, change['sd'])
        tau0 = max(tau0, evidence.samples / 4)
    # the own wanders' size and time bound the search (else it drifts off to a white
    # noise, a constant or a large stand-in for other effects)
    bounds = ((sd0 / 3, sd0 * 3), (max(tau0 / 4, MIN_TIME_CONSTANT), tau0 * 4)) \
        if own and not moved else ((1e-5, 2.0), (MIN_TIME_CONSTANT, 1e5))

    def make(x: Array, shared: bool = shared) -> TemporalDrift:
        sd = float(np.clip(math.exp(np.clip(x[0], -12, 2)), *bounds[0]))
        tau = float(np.clip(math.exp(np.clip(x[1], -3, 12)), *bounds[1]))
        return TemporalDrift(sensors, round(sd, 5), round(tau, 2), bool(shared))
    start = [math.log(sd0), math.log(tau0)]
    simplex = [start, [math.log(sd0 * 1.6), start[1]], [start[0], math.log(tau0 * 2.0)]]
    result = minimize(lambda x: evidence.objective([make(x)]), start, method='Nelder-Mead',
                      options={'maxfev': EVALUATIONS[bool(own and not moved)],
                               'initial_simplex': simplex})  # type: ignore[call-overload]
    effect, best = make(result.x), float(result.fun)
    if len(sensors) > 1:                  # the evidence for sharing can be weak: try both
        other = make(result.x, not shared)
        value = evidence.objective([other])
        if value < best:
            effect, best = other, value
    return effect, best, moved


def _unexplained_levels(levels: list[Row]) -> list[int]:
    """Sensors whose levels stay off after the best fixed gain and offset: run-to-run
    offsets a calibration cannot make (chi-square of the line's residuals, Holm)."""
    cells, p = by_sensor(levels), []
    for mine in cells.values():
        real, sim, se = (np.array(v) for v in zip(*[(r.real, r.sim, r.se) for r in mine]))
        p.append(1.0 if real.size < 4 or np.ptp(sim) < 1 else line_p(real, sim, se)[1])
    return significant(cells, p)


def _combined_excess(acf: list[Row]) -> list[int]:
    """Sensors whose autocorrelations lie above the simulation's taken together
    (Stouffer's z over conditions and lags, Holm over sensors)."""
    cells = by_sensor(acf)
    z = np.array([np.sum([r.z for r in v]) / np.sqrt(len(v)) for v in cells.values()])
    return significant(cells, sps.norm.sf(z))
