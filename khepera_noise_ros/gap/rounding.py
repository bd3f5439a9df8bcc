"""Where the simulator rounds the reading, chosen from the value lattice of the data.

A sensor's converter rounds the noisy analogue signal once; the paper's simulator
rounds the light level and adds integer noise to it.  The two put different shares
of readings on each value (mode share, granularity, the pile at the ends), and no
effect of the vocabulary is that difference.  ``choose`` compares the fitting part's
lattice statistics under both settings, given the effects found so far, and keeps
the other setting only when it lowers their discrepancy significantly and by a
real share; ``retarget`` gives a target the chosen setting (docs/diagnosis.md).
"""
from __future__ import annotations

import copy
import dataclasses

import numpy as np

from ..core.noise import ROUNDINGS
from .where import MARGIN

LATTICE = frozenset({'mode_share', 'granularity', 'pileup'})
MIN_SHARE = 0.25        # of the lattice statistics' discrepancy the other setting must remove
ALPHA = 0.05            # one-sided, paired bootstrap over the real data's replicates
REPLICATES = 60


def with_rounding(config, rounding: str):
    """``config`` (a SimConfig) whose noise model rounds at ``rounding``."""
    return dataclasses.replace(config, noise=dataclasses.replace(config.noise,
                                                                 rounding=rounding))


def retarget(target, rounding: str):
    """``target`` simulating with ``rounding`` (its real statistics shared: they do not
    depend on the simulator)."""
    if target.config.noise.rounding == rounding:
        return target
    out = copy.copy(target)
    out.config = with_rounding(target.config, rounding)
    return out


def lattice(target, c) -> tuple[float, np.ndarray]:
    """(the lattice statistics' part of comparison ``c``'s discrepancy, the same for each
    bootstrap replicate of the real data against ``c``'s simulated side)."""
    mask = np.array([k.family in LATTICE for k in c.keys], bool)
    if not mask.any():
        return 0.0, np.zeros(max(target.real.values.shape[0] - 1, 1))
    index = target.real.index()
    rows = [index[k] for k, m in zip(c.keys, mask) if m]
    with np.errstate(divide='ignore', invalid='ignore'):
        z = (target.real.values[1:, rows] - c.sim[mask][None]) / c.se[mask][None]
    z = np.nan_to_num(z, nan=0.0, posinf=1e3, neginf=-1e3)
    reps = (np.clip(np.abs(z) - MARGIN, 0.0, None) ** 2).sum(axis=1)
    d = float((np.clip(np.abs(c.z[mask]) - MARGIN, 0.0, None) ** 2).sum())
    return d, reps


def choose(target, effects=(), alpha: float = ALPHA) -> dict:
    """Which rounding the lattice statistics of ``target`` (the fitting part) prefer,
    with ``effects`` in the simulator: the target's own unless the other lowers their
    discrepancy by ``MIN_SHARE`` and in ``1 - alpha`` of the paired replicates.

    Returns:
        {'rounding', 'given' (the target's setting), 'lattice' {setting: discrepancy},
        'p_value', 'note'}; no lattice statistics (readings not integers): the given.
    """
    given = target.config.noise.rounding
    other = next(r for r in ROUNDINGS if r != given)
    effects = list(effects)
    d0, reps0 = lattice(target, target.compare(effects, replicates=REPLICATES))
    alt = retarget(target, other)
    d1, reps1 = lattice(alt, alt.compare(effects, replicates=REPLICATES))
    diff = reps0 - reps1
    diff = diff + (d0 - d1) - np.median(diff)       # centred on the estimate (paired_p)
    p = float((np.sum(diff <= 0) + 1) / (diff.size + 1))
    better = d0 > 0 and d1 <= (1.0 - MIN_SHARE) * d0 and p < alpha
    out = {'rounding': other if better else given, 'given': given,
           'lattice': {given: d0, other: d1}, 'p_value': p}
    if d0 <= 0 and d1 <= 0:
        out['note'] = 'no value-lattice statistic differs: the given rounding is kept'
    else:
        out['note'] = (f"value-lattice statistics' discrepancy {d0:.1f} rounding at the "
                       f"{given}, {d1:.1f} at the {other} (p = {p:.3f}): "
                       + (f'the simulator rounds at the {other}' if better
                          else f'the {given} is kept'))
    return out
