"""Fitting a slow wander of the sensors' gain (``temporal_drift``): where, shared or each
sensor's own, how large and how slow.

Evidence: extra autocorrelation of the residuals, or of each sensor's own part
(``gap.ownwander``: what it does not share with the others), level offsets no fixed
calibration makes, or levels moving together from run to run (``gap.timesig``).  A
wander of each sensor's own also moves the run-to-run shared factor a little (the
mean of independent wanders), so where both show, a shared slow change and the own
wanders are both fitted and the simulator chooses between them.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import stats as sps
from scipy.optimize import minimize

from . import effects as fx
from . import ownwander, timesig
from .fitbase import Z_DETECT, Candidate, by_condition, channels, names, rows
from .groups import fast_evidence
from .where import ALPHA, Comparison, holm

MIN_TIME_CONSTANT = 0.5  # samples; below this a drift is white noise, not a drift
# The drift's search: 16 objectives, 10 in the box the own wander bounds (there the
# later steps gained less than the objective's noise between simulator seeds)
DRIFT_EVALUATIONS = (16, 10)


def drift(target, c: Comparison) -> Candidate:
    name = fx.TemporalDrift.name
    acf = [(k, r, s, z) for k, r, s, se, z in rows(c, 'autocorrelation')] or \
        [(k, r, s, z) for k, r, s, se, z in rows(c, 'loop_residual_autocorrelation')]
    own = ownwander.of_target(target)       # each sensor's own wander, shared noise out
    located = tuple(sorted(set(_combined_excess(acf)) | set(_unexplained_levels(c)) | set(own)))
    change = timesig.of_target(target)
    moved = bool(change and change['significant'])   # levels moving together over time
    if not located and not moved:
        return Candidate(name, None, 'no extra autocorrelation over time and no level '
                                     'offsets beyond a fixed calibration')
    searches = []
    if moved:
        searches.append(_search(target, c, acf, own, tuple(channels(target)), change))
    if located and (own or not moved):
        searches.append(_search(target, c, acf, own, located, None))
    effect, _, sensors, shared_change = min(searches, key=lambda s: s[1])
    kind = 'one shared wander' if effect.shared else 'a wander per sensor'
    how = f'; levels move together over time (sd {change["sd"]:.1%})' \
        if shared_change else ''
    return Candidate(name, effect, f'slow wander on {names(sensors)} ({kind}){how}')


def _search(target, c: Comparison, acf: list, own: dict, sensors: tuple, change):
    """(effect, objective, sensors, whether it is the shared change's) of one search: a
    slow change shared by all sensors from the run-to-run factors (``change``), or a
    wander on ``sensors`` (``change`` None) bounded by their own wanders' size and time."""
    moved = change is not None
    chans = channels(target)
    evidence = fast_evidence(target, c, 'slow')
    idx = [chans.index(s) for s in sensors]
    shared = moved or len(idx) > 1 and \
        evidence[np.ix_(idx, idx)][~np.eye(len(idx), dtype=bool)].mean() > Z_DETECT
    rho = {lag: np.mean([r - s for k, r, s, z in acf
                         if k.sensors[0] in sensors and k.part == f'lag {lag}'] or [np.nan])
           for lag in (1, 3)}
    if not np.isfinite(rho[1]):
        rho[1] = 0.0
    if not np.isfinite(rho[3]):          # closed loop: lag 1 only; as an AR(1) would
        rho[3] = max(rho[1], 0.0) ** 3
    a = float(np.clip((max(rho[3], 1e-3) / max(rho[1], 1e-3)) ** 0.5, 0.3, 0.995))
    if own:                              # the own parts' excess, lag 10 against lag 1
        r1, r10 = (np.median([v['acf'][lag] for v in own.values()]) for lag in (1, 10))
        a = float(np.clip((max(r10, 1e-3) / max(r1, 1e-3)) ** (1 / 9), 0.3, 0.995))
    tau0 = -1.0 / math.log(a)
    spread = by_condition(c, 'spread')
    level = by_condition(c, 'level')
    ratio = [spread[cond][s][0] / level[cond][s][1] for cond in spread for s in sensors
             if level.get(cond, {}).get(s, (0, 0))[1] > 0]
    sd0 = float(np.sqrt(max(rho[1], 0.01)) * np.mean(ratio)) if ratio else 0.01
    if own:
        sd0 = float(np.median([v['sd'] for v in own.values()])) or sd0
    if moved:             # start from the shared factors' spread, slow over the runs
        sd0 = max(sd0, change['sd'])
        tau0 = max(tau0, sum(len(r) for r in target.recordings) / 4)

    # the own wanders' size and correlation time bound the refinement (else it drifts off
    # to a white, a constant or a large proxy for other effects)
    bounds = ((sd0 / 3, sd0 * 3), (max(tau0 / 4, MIN_TIME_CONSTANT), tau0 * 4)) \
        if own and not moved else ((1e-5, 2.0), (MIN_TIME_CONSTANT, 1e5))

    def make(x, shared=shared):
        # bounded so that the model can always run: a time constant of 0 has no AR(1)
        sd = float(np.clip(math.exp(np.clip(x[0], -12, 2)), *bounds[0]))
        tau = float(np.clip(math.exp(np.clip(x[1], -3, 12)), *bounds[1]))
        return fx.TemporalDrift(sensors, round(sd, 5), round(tau, 2), bool(shared))
    result = minimize(lambda x: target.objective([make(x)]), [math.log(sd0), math.log(tau0)],
                      method='Nelder-Mead', options={
                          'maxfev': DRIFT_EVALUATIONS[bool(own and not moved)],
                          'initial_simplex': [
                              [math.log(sd0), math.log(tau0)],
                              [math.log(sd0 * 1.6), math.log(tau0)],
                              [math.log(sd0), math.log(tau0 * 2.0)]]})
    effect, best = make(result.x), float(result.fun)
    if len(sensors) > 1:                  # the evidence for sharing can be weak: try both
        other = make(result.x, not shared)
        value = target.objective([other])
        if value < best:
            effect, best = other, value
    return effect, best, sensors, moved


def _unexplained_levels(c: Comparison) -> tuple:
    """Sensors whose levels stay off after the best fixed gain and offset: run-to-run
    offsets a calibration cannot make (chi-square of the line's residuals, Holm)."""
    level_rows = rows(c, 'level')
    sensors = sorted({k.sensors[0] for k, *_ in level_rows})
    p = []
    for sensor in sensors:
        real, sim, se = (np.array(v) for v in zip(*[(r, m, e) for k, r, m, e, z in level_rows
                                                    if k.sensors[0] == sensor]))
        if real.size < 4 or np.ptp(sim) < 1:
            p.append(1.0)
            continue
        line = np.polyval(np.polyfit(sim, real, 1, w=1 / se), sim)
        p.append(float(sps.chi2.sf((((real - line) / se) ** 2).sum(), real.size - 2)))
    adjusted = holm(np.array(p)) if p else np.array([])
    return tuple(s for s, q in zip(sensors, adjusted) if q < ALPHA)


def _combined_excess(acf_rows) -> tuple:
    """Sensors whose statistics lie above the simulation taken together (Stouffer's z over
    conditions and lags, Holm over sensors)."""
    by: dict = {}
    for k, r, s, z in acf_rows:
        by.setdefault(k.sensors[0], []).append(z)
    sensors = sorted(by)
    z = np.array([np.sum(by[s]) / np.sqrt(len(by[s])) for s in sensors])
    p = holm(sps.norm.sf(z))
    return tuple(s for s, ps in zip(sensors, p) if ps < ALPHA)
