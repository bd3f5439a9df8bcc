"""A compound step judged on the part of the statistics it acts on.

A dropout acts only on the dropout counts, a lattice seen in closed loop only on the
loop's value statistics, a sensor's noise beside a loop effect only on the closed
loop's noise statistics.  The paired bootstrap of the whole comparison adds the other
parts' replicate noise to such a step: a step that removes all of a small part's
discrepancy, significantly on that part's own replicates, can fail the overall test.
Here a step counts by one part when on that part's own paired replicates it is
significant (alpha over the number of parts tried) and removes ``min_local`` of the
part before any effect or ``min_left`` of what is left, while no other part gets
significantly worse on its own replicates, the total does not rise, and the same holds
against a second simulator seed.  The parts themselves (``split``) and the chance
level of a part (``chance``) are the compound selection's.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Rule:
    alpha: float              # one-sided, paired bootstrap, before the correction for parts
    min_local: float          # share of the part's discrepancy before any effect
    min_left: float           # ... or of what the chosen effects leave of it
    confirm_seed: int         # offset of the second simulator seed


def paired_p(before: np.ndarray, after: np.ndarray, d_prev: float, d_new: float) -> float:
    """One-sided p that ``after`` does not lower the discrepancy: the paired replicate
    differences, centred on the estimate's difference (as ``diagnose._score`` does)."""
    diff = before - after
    diff = diff + (d_prev - d_new) - np.median(diff)
    return float((np.sum(diff <= 0) + 1) / (diff.size + 1))


def passing(b, split, chance, first, current, after, rule: Rule) -> str:
    """The part by which the step from ``current`` to ``after`` (held-out comparisons of
    target ``b``; ``first``: before any effect) counts, '' for none.  ``split(c)`` gives
    each part's comparison, ``chance(n)`` the discrepancy n statistics reach with no gap."""
    if after.discrepancy >= current.discrepancy:
        return ''
    f, c, a = split(first), split(current), split(after)
    parts = [p for p in c if p in a]
    tried = [p for p in parts if c[p].discrepancy > chance(len(c[p].keys))]
    if not tried:
        return ''
    reps = {p: (b.replicate_discrepancies(c[p]), b.replicate_discrepancies(a[p]))
            for p in parts}
    for p in parts:             # no part may move away significantly (one-sided)
        d1, d2 = c[p].discrepancy, a[p].discrepancy
        if d2 > d1 and paired_p(reps[p][1], reps[p][0], d2, d1) < rule.alpha:
            return ''
    best, gain = '', 0.0
    for p in tried:
        d0 = f[p].discrepancy if p in f else 0.0
        d1, d2 = c[p].discrepancy, a[p].discrepancy
        if d2 >= d1:
            continue
        local = (d1 - d2) / d0 if d0 > 0 else 0.0
        left = (d1 - d2) / d1
        if local < rule.min_local and left < rule.min_left:
            continue
        if paired_p(reps[p][0], reps[p][1], d1, d2) >= rule.alpha / len(tried):
            continue
        if max(local, left) > gain:
            best, gain = p, max(local, left)
    return best


def confirmed(b, split, chance, first, chosen: list, effects: list, part: str,
              rule: Rule) -> bool:
    """Does the step count by the same part against a second simulated side (another
    simulator seed)?  The paired bootstrap resamples the real data only; the
    simulator's own noise can make a step of a small part's size."""
    other = copy.copy(b)
    other.seed = b.seed + rule.confirm_seed
    prev, new = other.compare(chosen), other.compare(effects)
    return passing(other, split, chance, first, prev, new, rule) == part


def counts(b, split, chance, first, current, after, chosen: list, effects: list,
           rule: Rule) -> str:
    """'part: <name>' when the step counts by one part (``passing``) on both simulator
    seeds, else ''."""
    part = passing(b, split, chance, first, current, after, rule)
    if part and confirmed(b, split, chance, first, chosen, effects, part, rule):
        return f'part: {part}'
    return ''
