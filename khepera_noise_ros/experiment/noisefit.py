"""Fitting the paper's combination noise model to a stationary recording ("observe the robot").

The paper's recipe (section 3): observe the sensors at fixed positions, designate
as dependence groups the sets of sensors whose noise moves together, and note
the degree of correlation.  Here each step is measured:

* groups: sensors clustered by the evidence that their residuals (readings about
  each run's mean) are correlated, combined over conditions (``gap.groups``);
* levels: in the model a sensor's variance is (d g)^2/3 + (i L)^2/3 and two group
  members share (d g)^2/3 (g the group's mean level, L the sensor's), so d and i
  follow from the pooled covariances by least squares; because getnoise
  truncates toward zero, they are then calibrated by simulating the model at the
  recorded levels and scaling until its moments match;
* distribution: uniform or normal, whichever gives kurtosis closer to the data's
  (the sum of a few uniform parts is flatter than normal);
* level dependence: per condition the same fit shows whether d and i change with
  the light; if the data reject the model's proportional scaling, an
  ``intensity_dependent_noise`` effect is fitted on part of the data and kept only
  if it shrinks the discrepancy on the rest (``gap.diagnose``).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..core.khepera import SENSORS
from ..core.noise import DISTRIBUTIONS, NoiseModel
from ..effects import IntensityDependentNoise
from ..effects.correlated_noise import cluster
from ..recording import Recording
from ..gap import split
from ..gap.evidence import correlation_evidence
from ..gap.protocol import check, kind, runs
from ..gap.replay import Replayer
from ..gap.select import MIN_REDUCTION
from ..gap.target import Target
from ..simconfig import SimConfig

CALIBRATION_ROUNDS = 3


@dataclass
class NoiseFit:
    groups: list                  # dependence groups (channel numbers)
    dependent: float
    independent: float
    distribution: str
    by_condition: list = field(default_factory=list)   # the combination model per condition
    effects: tuple = ()           # level dependence beyond the model, if the data show it
    notes: list = field(default_factory=list)

    def noise_model(self) -> NoiseModel:
        """The core model; a ValueError when groups name channels beyond the Khepera's 8."""
        model = 'combination' if self.groups else 'independent'
        return NoiseModel(model, self.dependent if self.groups else 0.0, self.independent,
                          tuple(tuple(g) for g in self.groups), self.distribution)


def fit(rec: Recording, base: SimConfig = SimConfig(), seed: int = 0,
        level_dependence: bool = True) -> NoiseFit:
    """The combination model that best describes the stationary recording ``rec``."""
    check([rec])
    if kind(rec) != 'stationary':
        raise ValueError('fit needs a stationary recording (the robot held at fixed headings); '
                         'this one is closed-loop')
    result = _combination(rec, base, seed)
    if not level_dependence or result.notes[-1].startswith('levels from moments only'):
        return result
    (_, fit_part), (_, test_part) = [p[0] for p in split.split([rec])]
    structures = {name: make(fit_part, base, seed) for name, make in STRUCTURES.items()}
    scores = {name: Target([test_part], _config(f, base, rec.channels), seed + 3,
                           base='observed', replicates=100).compare(f.effects).discrepancy
              for name, f in structures.items()}
    best = min(scores, key=scores.get)
    plain = scores['combination']
    result.notes.append('held-out discrepancy by structure: ' + ', '.join(
        f'{n} {v:.0f}' for n, v in scores.items()))
    if best != 'combination' and plain > 0 and 1 - scores[best] / plain >= MIN_REDUCTION:
        chosen = STRUCTURES[best](rec, base, seed)
        chosen.by_condition = result.by_condition
        chosen.notes = [n for n in result.notes if not n.startswith('distribution')] \
            + [n for n in chosen.notes if n.startswith('distribution')]
        chosen.notes.append(f'level dependence: the data show noise growing with the light '
                            f'level beyond the model\'s proportional scaling; {best} removes '
                            f'{1 - scores[best] / plain:.0%} of the plain model\'s held-out '
                            f'discrepancy')
        return chosen
    result.notes.append('level dependence: none beyond the model\'s proportional scaling')
    return result


def _combination(rec: Recording, base: SimConfig, seed: int) -> NoiseFit:
    """Groups, levels (calibrated by simulation) and distribution of the paper's model."""
    used = rec.channels_used
    stats = Target([rec], base, seed, base='observed').real
    evidence = correlation_evidence(stats.keys, stats.estimate, np.sqrt(stats.variance), used)
    groups = [[used[i] for i in g] for g in cluster(evidence)]
    d, i = _solve(_moments(rec, groups))
    result = NoiseFit(groups, d, i, 'uniform')
    result.by_condition = _by_condition(rec, groups)
    try:
        _config(result, base, rec.channels)
    except ValueError as exc:
        result.notes.append(f'levels from moments only, not calibrated by simulation: {exc}')
        return result
    for _ in range(CALIBRATION_ROUNDS):
        sim_d, sim_i = _solve(_moments(_simulate(rec, result, base, seed), groups))
        result.dependent = _scaled(result.dependent, d, sim_d)
        result.independent = _scaled(result.independent, i, sim_i)
    result.distribution = _distribution(rec, result, base, seed)
    return result


def _combination_and_level(rec: Recording, base: SimConfig, seed: int) -> NoiseFit:
    """The combination model, plus shared noise that grows with the level on top."""
    result = _combination(rec, base, seed)
    return _with_intensity(rec, result, base, seed)


def _independent_and_level(rec: Recording, base: SimConfig, seed: int) -> NoiseFit:
    """Independent noise at the level the brightest quarter of readings shows (where noise
    that grows with the level is smallest), plus shared level-dependent noise on top."""
    levels = [rec.readings[r][:, rec.channels_used].mean(axis=0) for r in runs(rec)]
    bright = float(np.quantile(np.concatenate(levels), 0.25))
    _, i = _solve(_moments(rec, [], bright))
    result = NoiseFit([], 0.0, i, 'uniform')
    for _ in range(CALIBRATION_ROUNDS):
        _, sim_i = _solve(_moments(_simulate(rec, result, base, seed), [], bright))
        result.independent = _scaled(result.independent, i, sim_i)
    return _with_intensity(rec, result, base, seed)


def _with_intensity(rec: Recording, result: NoiseFit, base: SimConfig, seed: int) -> NoiseFit:
    target = Target([rec], _config(result, base, rec.channels), seed, base='observed',
                    replicates=100)
    found = IntensityDependentNoise.fit(target.evidence(target.compare()))
    result = dataclasses.replace(result, effects=(found.effect,) if found.effect else (),
                                 notes=[n for n in result.notes
                                        if not n.startswith('distribution')])
    result.distribution = _distribution(rec, result, base, seed)
    return result


STRUCTURES = {'combination': _combination,
              'combination + intensity_dependent_noise': _combination_and_level,
              'independent + intensity_dependent_noise': _independent_and_level}


def _scaled(value: float, wanted: float, got: float) -> float:
    return float(np.clip(value * wanted / got, 0.0, 1.0)) if got > 0 else value


def _moments(rec: Recording, groups, max_level: float = np.inf) -> np.ndarray:
    """Sums for the least-squares levels: [cov, g^2/3] over group pairs, [var, (g^2, L^2)/3]
    over sensors (those with levels up to ``max_level``), each pooled over runs."""
    rows_cov, rows_var = [], []
    member = {s: g for g in groups for s in g}
    for run in runs(rec):
        x = rec.readings[run][:, rec.channels_used]
        if x.shape[0] < 3:
            continue
        level = x.mean(axis=0)
        cov = np.cov(x, rowvar=False)
        where = {s: k for k, s in enumerate(rec.channels_used)}
        for g in groups:
            idx = [where[s] for s in g]
            g2 = np.mean(level[idx]) ** 2 / 3.0
            for a in range(len(idx)):
                for b in range(a + 1, len(idx)):
                    rows_cov.append((cov[idx[a], idx[b]], g2))
        for s, k in where.items():
            if level[k] > max_level:
                continue
            g2 = np.mean(level[[where[m] for m in member[s]]]) ** 2 / 3.0 if s in member else 0.0
            rows_var.append((cov[k, k], g2, level[k] ** 2 / 3.0))
    return np.array(rows_cov).reshape(-1, 2), np.array(rows_var).reshape(-1, 3)


def _solve(moments) -> tuple[float, float]:
    """(d, i) from the moment rows: cov = d^2 g^2/3, var = d^2 g^2/3 + i^2 L^2/3."""
    cov, var = moments
    d2 = max(float((cov[:, 0] * cov[:, 1]).sum() / (cov[:, 1] ** 2).sum()), 0.0) \
        if cov.size and (cov[:, 1] > 0).any() else 0.0
    rest = var[:, 0] - d2 * var[:, 1]
    i2 = max(float((rest * var[:, 2]).sum() / (var[:, 2] ** 2).sum()), 0.0) \
        if (var[:, 2] > 0).any() else 0.0
    return float(np.sqrt(d2)), float(np.sqrt(i2))


def _config(result: NoiseFit, base: SimConfig, channels: int) -> SimConfig:
    """The simulator with the fitted model; a ValueError if it cannot simulate the data
    (the model's dependence groups name Khepera sensors 0..7 only)."""
    if any(s >= SENSORS for g in result.groups for s in g):
        raise ValueError(f'the model\'s dependence groups name sensors 0..{SENSORS - 1}; '
                         f'the fitted groups {result.groups} cannot be simulated')
    return dataclasses.replace(base, noise=result.noise_model())


def _simulate(rec: Recording, result: NoiseFit, base: SimConfig, seed: int) -> Recording:
    """The model at the recording's own levels (observed base), one copy."""
    return Replayer(rec, _config(result, base, rec.channels), 'observed').replay(seed=seed + 17)


def _distribution(rec: Recording, result: NoiseFit, base: SimConfig, seed: int) -> str:
    """The model's distribution whose kurtosis (with any effects on top) fits best."""
    scores = {}
    for name in DISTRIBUTIONS:
        trial = dataclasses.replace(result, distribution=name)
        target = Target([rec], _config(trial, base, rec.channels), seed, base='observed',
                        replicates=100)
        scores[name] = target.objective(result.effects, families=('kurtosis',), margin=0.0)
    result.notes.append('distribution: ' + ', '.join(f'{n} kurtosis chi-square {v:.1f}'
                                                     for n, v in scores.items()))
    return min(scores, key=scores.get)


def _by_condition(rec: Recording, groups) -> list[dict]:
    out = []
    for label in rec.conditions():
        part = rec.select(rec.condition == label)
        d, i = _solve(_moments(part, groups))
        x = part.readings[:, part.channels_used]
        corr = _within_group_correlation(part, groups)
        out.append({'condition': label, 'groups': groups, 'mean_level': float(np.mean(x)),
                    'dependent': d, 'independent': i, 'within_group_correlation': corr})
    return out


def _within_group_correlation(rec: Recording, groups) -> float | None:
    values = []
    for run in runs(rec):
        x = rec.readings[run]
        if x.shape[0] < 3:
            continue
        with np.errstate(invalid='ignore', divide='ignore'):   # a constant channel: NaN
            c = np.corrcoef(x, rowvar=False)
        values += [c[a, b] for g in groups for ai, a in enumerate(g) for b in g[ai + 1:]
                   if np.isfinite(c[a, b])]
    return float(np.mean(values)) if values else None
