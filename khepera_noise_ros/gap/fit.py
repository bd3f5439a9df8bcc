"""Fitting each candidate effect, location first, to one part of the real data.

Every fitter looks at the comparison of that part (real against the plain
simulator) for the fingerprint its effect leaves, picks the sensors or groups
that carry it, takes first estimates of the parameters from moments, and then
refines them by minimising the simulator-with-effect's discrepancy (common
random numbers, so a handful of evaluations suffice).  A fitter that finds no
fingerprint, or has no data that could show one, returns no effect and says why.

Fingerprints (what the statistics of ``gap.statistics`` show):
  sensor_gain_offset         per-sensor levels off, linearly in the level
  saturation_quantization    readings piled up at a limit the simulator exceeds (gap.pileup);
                             a value grid; dropouts
  correlated_noise           pairs more correlated than simulated (clustered into groups)
  intensity_dependent_noise  extra shared spread that grows steeply with the level
  temporal_drift             extra autocorrelation; level offsets no fixed calibration makes
  sensor_latency             a step response that lags; turn responses moved to lag 1
  actuator_turn_error        the response to a turn scaled, or scattered (gap.fitturn)
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import stats as sps

from ..recording import reading_range
from . import effects as fx
from . import closednoise, fitlatency, fitturn, limits, pileup, spreadlaw, timesig
from .fitbase import Z_DETECT, Candidate  # noqa: F401 (Candidate re-exported)
from .fitbase import by_condition as _by_condition, channels as _channels
from .fitbase import golden as _golden, names as _names, rows as _rows
from .fitdrift import drift
from .groups import cluster, fast_evidence as _fast_evidence
from .statistics import STEP_LAGS
from .target import Target
from .where import ALPHA, Comparison, holm

ANCHOR = 525.0          # gain is about the dark end of the Khepera's scale


# --- sensor_gain_offset ----------------------------------------------------------------

def gain_offset(target: Target, c: Comparison) -> Candidate:
    name = fx.SensorGainOffset.name
    rows = _rows(c, 'level')
    if not rows or target.base == 'observed':
        return Candidate(name, None, 'no levels from the light model to compare')
    change = timesig.of_target(target)
    if change and change['significant']:      # a gain or offset is what the shared change
        rows = timesig.steady_rows(rows, target, change)       # over time leaves
    sensors = sorted({k.sensors[0] for k, *_ in rows})
    chi = {s: sum(z * z for k, *_, z in rows if k.sensors[0] == s) for s in sensors}
    dof = {s: sum(1 for k, *_ in rows if k.sensors[0] == s) for s in sensors}
    p = holm(np.array([sps.chi2.sf(chi[s], dof[s]) for s in sensors]))
    located = [s for s, ps in zip(sensors, p) if ps < ALPHA]
    if not located:
        return Candidate(name, None, 'no sensor\'s levels differ significantly' + (
            ' beyond a shared change over time' if change and change['significant'] else ''))
    gains, offsets = [], []
    for s in located:
        real = np.array([r for k, r, *_ in rows if k.sensors[0] == s])
        sim = np.array([m for k, _, m, *_ in rows if k.sensors[0] == s])
        g, a = np.polyfit(sim, real, 1) if np.ptp(sim) > 1 else (1.0, real.mean() - sim.mean())
        gains.append(round(float(g), 4))
        offsets.append(round(float(a - ANCHOR * (1 - g)), 2))
    effect = fx.SensorGainOffset(tuple(located), tuple(gains), tuple(offsets), ANCHOR)
    return Candidate(name, effect, f'levels of {_names(located)} off the light model')


# --- saturation_quantization -----------------------------------------------------------

def saturation(target: Target, c: Comparison) -> Candidate:
    name = fx.SaturationQuantization.name
    grains = _rows(c, 'granularity') or _rows(c, 'loop_granularity')   # closed loop alone
    grid_flag = {k.sensors[0] for k, r, s, se, z in grains if z > Z_DETECT}
    real = np.concatenate([r.readings for r in target.recordings])
    sim = np.concatenate([r.readings for r in target.simulate()])
    rec = target.recordings[0]
    found = pileup.limits(real, sim, rec.channels_used, reading_range(rec.manifest, rec.channels))
    # the limit holding most readings at each end, with the sensors piled up there
    low, high = (pileup.strongest(found, end) for end in (0, 1))
    grid = {}
    for sensor in rec.channels_used:
        x, y = real[:, sensor], sim[:, sensor]
        x, y = x[np.isfinite(x)], y[np.isfinite(y)]
        lattice = _grid(x[(x > x.min()) & (x < x.max())])
        # without granularity statistics the simulator's own readings not lying on the
        # real lattice is the evidence
        measured = sensor in grid_flag if grains else \
            _grid(y[(y > y.min()) & (y < y.max())]) != lattice
        if lattice[0] > 1 and measured:
            grid[sensor] = lattice
    stationary = target.of_kind('stationary')
    lost = limits.dropouts(target.recordings, target.simulate())    # closed loop too
    if not (low or high or grid or lost):
        return Candidate(name, None, 'no readings held at a limit, no coarse value grid and '
                                     'no dropouts')
    drop = {}
    if lost:
        values = [v for v, _ in lost.values()]
        drop = {'dropout': round(float(np.median([r for _, r in lost.values()])), 5),
                'dropout_value': max(set(values), key=values.count)}
    lattices = list(grid.values())
    step, origin = max(set(lattices), key=lattices.count) if lattices else (1, 0)
    top = max(ANCHOR, *(v for v in reading_range(rec.manifest, rec.channels)
                        if np.isfinite(v)), *(v for v, _ in lost.values()))
    options = []
    for use_low in ([False, True] if low else [False]):
        for use_high in ([False, True] if high else [False]):
            # with dropouts, a grid is tried without its lattice too: only what is needed
            for use_grid in ([False, True] if grid and lost else [bool(grid)]):
                sensors = (set(grid) if use_grid else set()) | set(lost) | \
                    (set(low['sensors']) if use_low else set()) | \
                    (set(high['sensors']) if use_high else set())
                if sensors:
                    options.append(fx.SaturationQuantization(
                        tuple(sorted(sensors)),
                        low=low['value'] if use_low else 0.0,
                        high=high['value'] if use_high else top,
                        step=float(step) if use_grid else 1.0,
                        origin=float(origin) if use_grid else 0.0, **drop))
    kinds = ('stationary',) if stationary else None     # closed loop alone: judge there
    effect = min(options, key=lambda e: target.objective([e], kinds, limits=True))
    if lost:
        effect = limits.rescaled(target, effect, sorted(lost))
    what = [w for w, found in ((f'clipped below at {effect.low:g}', effect.low > 0),
                               (f'clipped above at {effect.high:g}', effect.high < top),
                               ('on a grid', effect.step > 1),
                               (f'dropping out to {effect.dropout_value:g} at rate '
                                f'{effect.dropout:.2%}', effect.dropout > 0)) if found]
    return Candidate(name, effect, f'{_names(effect.sensors)} {" and ".join(what)}')


def _grid(x: np.ndarray) -> tuple[int, int]:
    """(step, origin): the coarsest lattice origin + k * step (step 2..32) on which nearly
    all integer readings ``x`` lie, else (1, 0)."""
    if x.size < 20 or not np.all(x == np.round(x)):
        return 1, 0
    values, weight = np.unique(x, return_counts=True)    # a few hundred distinct readings
    for q in range(32, 1, -1):
        counts = np.bincount(np.mod(values, q).astype(np.int64), weights=weight)
        if counts.max() >= 0.95 * x.size:
            return q, int(counts.argmax())
    return 1, 0


# --- correlated_noise ------------------------------------------------------------------

def correlated(target: Target, c: Comparison) -> Candidate:
    name = fx.CorrelatedNoise.name
    channels = _channels(target)
    evidence = _fast_evidence(target, c)
    groups = [tuple(channels[i] for i in g) for g in cluster(evidence)]
    if not groups:
        return Candidate(name, None, 'no sensors whose noise is more correlated than simulated')
    start = _shared_strength(c, groups)
    first = start
    if not _rows(c, 'correlation'):   # closed loop only: the default start caps the search
        first = closednoise.shared_strength(c, groups, target.real) or start
    effect = _refine(target, lambda s: fx.CorrelatedNoise(tuple(groups), s), first)
    # shared noise of a fixed size in readings (a supply, a converter), not a share of
    # the level: one more form of the same effect, kept if the simulator says so
    level = np.mean([r for k, r, *_ in _rows(c, 'level')] or [ANCHOR / 2])
    fixed = _refine(target, lambda s: fx.CorrelatedNoise(tuple(groups), 0.0, s),
                    start * level, evaluations=5)
    if target.objective([fixed]) < target.objective([effect]):
        effect = fixed
    return Candidate(name, effect, f'excess correlation clusters into {_groups(groups)}')


def _shared_strength(c: Comparison, groups) -> float:
    """Moment estimate of shared noise sd as a fraction of the level: excess covariance
    within the groups over the mean squared level."""
    level, spread = _by_condition(c, 'level'), _by_condition(c, 'spread')
    num = den = 0.0
    for k, r, s, *_ in _rows(c, 'correlation'):
        for g in groups:
            if set(k.sensors) <= set(g):
                a, b = k.sensors
                sr = [spread[k.condition][x][0] for x in (a, b)]
                ss = [spread[k.condition][x][1] for x in (a, b)]
                num += r * sr[0] * sr[1] - s * ss[0] * ss[1]
                den += np.mean([level[k.condition][x][1] for x in g]) ** 2
    return float(np.sqrt(max(num, 0.0) / den)) if den > 0 and num > 0 else 0.01


def _refine(target: Target, make, start: float, kinds=('stationary',), evaluations: int = 7):
    """The effect ``make(x)`` with x refined on a log scale around ``start``."""
    start = float(np.clip(start, 1e-5, 1e3)) if np.isfinite(start) else 0.01
    kinds = _present(target, kinds)
    lo, hi = math.log(start / 3), math.log(start * 3)
    best = _golden(lambda u: target.objective([make(math.exp(u))], kinds), lo, hi,
                   evaluations)
    return make(round(math.exp(best), 5))


# --- intensity_dependent_noise ---------------------------------------------------------

def intensity(target: Target, c: Comparison) -> Candidate:
    """Extra spread that follows a law of the level (``gap.spreadlaw``): on the sensors
    whose fast noise is more correlated than simulated (one shared draw), else on those
    with extra spread (a draw per sensor)."""
    name = fx.IntensityDependentNoise.name
    channels = _channels(target)
    evidence = _fast_evidence(target, c)
    clusters = cluster(evidence)
    if clusters:
        best = max(clusters, key=lambda g: evidence[np.ix_(g, g)].sum())
        sensors, shared = tuple(channels[i] for i in best), True
    else:
        sensors = tuple(sorted({k.sensors[0] for k, r, s, se, z in _rows(c, 'spread') +
                                closednoise.spread_rows(c) if z > Z_DETECT}))
        shared = False
    if not sensors:
        return Candidate(name, None, 'no extra spread or shared noise to explain')
    cells = [(s, r * r - m * m) for k, r, m, *_ in _rows(c, 'spread') if k.sensors[0] in sensors
             for s in [_level(c, k)] if s is not None] + closednoise.spread_cells(
                 c, sensors, target.real)
    options = [fx.IntensityDependentNoise(sensors, round(k, 6), e, ANCHOR, round(c0, 4), d,
                                          shared)
               for d, e, c0, k, _ in spreadlaw.laws(cells)]
    options = [o for o in options if o.strength > 0 or o.constant > 0]
    # a constant part is poorly fixed by the unweighted fit (the darkest cells dominate;
    # other effects' transients add to them): the simulator also judges each law without
    options += [dataclasses.replace(o, constant=0.0) for o in options
                if o.constant > 0 and o.strength > 0]
    if not options:
        return Candidate(name, None, 'extra spread fits no spread law')
    best_effect = min(options, key=lambda e: target.objective([e]))
    if best_effect.strength > 0:
        best_effect = _refine(target, lambda s: dataclasses.replace(best_effect, strength=s),
                              best_effect.strength, evaluations=5)
    law = spreadlaw.describe(best_effect.direction, best_effect.exponent,
                             best_effect.constant, best_effect.strength)
    kind = 'one shared draw' if shared else 'a draw per sensor'
    return Candidate(name, best_effect, f'extra spread on {_names(sensors)}: {law}, {kind}')


def _level(c: Comparison, key) -> float | None:
    """The simulated level of ``key``'s cell (the first level row of that cell)."""
    levels = c.__dict__.get('_levels')
    if levels is None:          # one look-up table per comparison, not a scan per cell
        levels = {}
        for k, r, s, *_ in _rows(c, 'level'):
            levels.setdefault((k.sensors, k.condition, k.part), s)
        c.__dict__['_levels'] = levels
    return levels.get((key.sensors, key.condition, key.part))


# --- sensor_latency --------------------------------------------------------------------

def latency(target: Target, c: Comparison) -> Candidate:
    name = fx.SensorLatency.name
    steps = _rows(c, 'step_response')
    first = [(k.sensors[0], r) for k, r, s, se, z in steps
             if k.part.startswith('sample 0') and z > Z_DETECT]
    if first:
        sensors = tuple(sorted(s for s, _ in first))
        lag = {}
        for k, r, *_ in steps:
            if k.sensors[0] in sensors:
                lag[k.sensors[0]] = lag.get(k.sensors[0], 0.0) + float(np.clip(r, 0, 1))
        delay = max(1, int(round(np.median(list(lag.values())))))
        if delay >= STEP_LAGS:
            delay = _best_delay(target, sensors, range(STEP_LAGS, STEP_LAGS + 4))
        return Candidate(name, fx.SensorLatency(sensors, delay),
                         f'step response of {_names(sensors)} lags {delay} sample(s)')
    turned = {k.sensors[0] for k, r, s, se, z in _rows(c, 'sensor_turn_response')
              if abs(z) > Z_DETECT}
    if not turned:
        return Candidate(name, None, 'readings follow heading changes at once')
    # sensors whose turn responses pass for simulated can lag too: their closed-loop
    # noise residuals then take the earlier heading's light; the simulator judges on the
    # statistics other than noise ones (other sensor effects act on those too)
    options = {tuple(sorted(turned)), tuple(_channels(target)), tuple(sorted(turned | {
        k.sensors[0] for k, r, s, se, z in _rows(c, 'loop_residual_spread') if z > Z_DETECT}))}
    delayed = fitlatency.delayed_sensors(target.recordings)
    if delayed:
        options.add(delayed)
    families = {k.family for k in target.real.keys} - closednoise.FAMILIES
    sensors, delay = min(((o, d) for o in sorted(options) for d in (1, 2, 3)), key=lambda o: (
        target.objective([fx.SensorLatency(*o)], _present(target, ('closed_loop',)),
                         families)))
    return Candidate(name, fx.SensorLatency(sensors, delay),
                     f'turn responses of {_names(sensors)} delayed {delay} step(s)')


def _present(target: Target, kinds):
    """``kinds`` if the target has recordings of them, else all of its recordings."""
    return kinds if kinds is None or set(kinds) & set(target.kinds) else None


def _best_delay(target: Target, sensors, delays, kinds=('stationary',)) -> int:
    kinds = _present(target, kinds)
    return min(delays, key=lambda d: target.objective([fx.SensorLatency(sensors, d)], kinds))


# --- actuator_turn_error ---------------------------------------------------------------

def actuator(target: Target, c: Comparison) -> Candidate:
    """``gap.fitturn``: scale, random slip and creep of the turns."""
    return fitturn.actuator(target, c)


FITTERS = {fx.SensorGainOffset.name: gain_offset, fx.SaturationQuantization.name: saturation,
           fx.CorrelatedNoise.name: correlated, fx.IntensityDependentNoise.name: intensity,
           fx.TemporalDrift.name: drift, fx.SensorLatency.name: latency,
           fx.ActuatorTurnError.name: actuator}


def fit_all(target: Target, c: Comparison, names=tuple(FITTERS)) -> list[Candidate]:
    """Every named candidate fitted; one that fails is reported as not fitting."""
    return [fit_one(n, target, c) for n in names]


def fit_one(name: str, target: Target, c: Comparison, fitter=None) -> Candidate:
    """``FITTERS[name]`` run so that no failure escapes: an exception, or parameters the
    effect's own model cannot run (checked by a short trial), end as a candidate with
    no effect and a note saying why; the rest of the diagnosis carries on."""
    try:
        cand = (fitter or FITTERS[name])(target, c)
        if cand.effect is not None:
            runnable(cand.effect)
        return cand
    except Exception as exc:      # noqa: BLE001 - one candidate's failure is its own
        return Candidate(name, None, f'the fit failed: {type(exc).__name__}: {exc}')


def runnable(effect) -> None:
    """Raise ValueError unless ``effect`` passes its checks and runs a few steps."""
    effect = fx.from_dict(fx.to_dict(effect))
    if effect.stage == 'turn':
        out = effect.process(2, 8, np.random.default_rng(0))(np.array([10.0, -10.0]))
    else:
        channels = max([8] + [s + 1 for s in effect.sensors])
        apply = effect.process(2, channels, np.random.default_rng(0))
        out = [apply(np.full((channels, 2), 200.0)) for _ in range(3)][-1]
    if not np.all(np.isfinite(out)):
        raise ValueError(f'{effect.name} gives non-finite readings with {fx.to_dict(effect)}')


def _groups(groups) -> str:
    return ' '.join('{' + _names(g) + '}' for g in groups)
