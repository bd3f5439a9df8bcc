"""Compound diagnosis: a set of effects chosen by forward selection on held-out data.

A real robot has several unmodelled effects at once.  Starting from the best
single effect, each step fits every remaining candidate *jointly* with those
already chosen (the simulator the candidate is fitted against already has
them, ``Target.with_given``), scores simulator + chosen + candidate on the
held-out part, and keeps a candidate (the best first, then the next) only if
it lowers the held-out discrepancy significantly: by at least ``MIN_ADDED`` of
the discrepancy before any effect, or ``MIN_LOCAL`` of one protocol's own (a
turn error acts only on the closed-loop statistics), or ``MIN_LEFT`` of what
the chosen effects leave of one protocol's (checked again on a second
simulator seed), and in ``1 - alpha`` of the paired bootstrap replicates (the
same resampled real data against both simulators).  With the best candidate
the effects chosen earlier are refitted given the others (one backfitting
pass), each refit kept only where it lowers the *fitting* part's discrepancy,
the refitted set only where the held-out one does not rise.  Selection stops
when no candidate adds a significant share.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np

from . import effects as fx
from . import closednoise, dropout, fit
from .target import Target

MIN_ADDED = 0.005         # share of the discrepancy before any effect a step must remove
MIN_LOCAL = 0.10          # ... or this share of one protocol's own discrepancy (see below)
MIN_LEFT = 0.50           # ... or of what the chosen effects leave of one protocol's part
STEP_ALPHA = 0.05         # one-sided, paired bootstrap
FINGERPRINT_REPLICATES = 40
JOINT = 1                 # candidates per step refitted jointly with the chosen ones
CONFIRM_SEED = 5003       # offset of the second simulator seed a MIN_LEFT step is checked on


@dataclass
class Compound:
    effects: list                       # fitted effects, in the order chosen
    steps: list                         # one dict per chosen effect (diagnosis.json)
    discrepancy_before: float
    discrepancy_after: float
    comparison: object = None           # held-out comparison with every chosen effect
    replicates: np.ndarray | None = None
    rejected: list = field(default_factory=list)   # the best candidate that did not count

    @property
    def reduction(self) -> float:
        if self.discrepancy_before <= 0:
            return 0.0
        return 1.0 - self.discrepancy_after / self.discrepancy_before

    def to_json(self) -> dict:
        return {'chosen': self.steps, 'discrepancy_before': self.discrepancy_before,
                'discrepancy_after': self.discrepancy_after,
                'heldout_reduction': self.reduction, 'rejected': self.rejected,
                'min_added': MIN_ADDED, 'min_left': MIN_LEFT, 'step_alpha': STEP_ALPHA}


def entry(effect, note: str, d_before: float, d_after: float, d_prev: float,
          p: float) -> dict:
    params = fx.parameters(effect)
    if effect.name == fx.CorrelatedNoise.name:
        params['groups'] = effect.location
    return {'name': effect.name, 'sensors': list(effect.sensors), 'parameters': params,
            'discrepancy_after': d_after,
            'added_reduction': (d_prev - d_after) / d_before if d_before > 0 else 0.0,
            'cumulative_reduction': 1.0 - d_after / d_before if d_before > 0 else 0.0,
            'p_value': p, 'note': note}


def paired_p(before: np.ndarray, after: np.ndarray, d_prev: float, d_new: float) -> float:
    """One-sided p that ``after`` does not lower the discrepancy: the paired replicate
    differences, centred on the estimate's difference (as ``diagnose._score`` does)."""
    diff = before - after
    diff = diff + (d_prev - d_new) - np.median(diff)
    return float((np.sum(diff <= 0) + 1) / (diff.size + 1))


def select(a: Target, b: Target, first, names, d_before: float, before_reps: np.ndarray,
           before=None, log=None) -> Compound:
    """Forward selection from ``first`` (the best single effect: its fitted effect, note,
    held-out comparison and replicate discrepancies) over the candidate ``names``;
    ``before`` is the held-out comparison without effects."""
    effect0, note0, cmp0, reps0 = first
    first_cmp = before if before is not None else b.compare()
    d_prev = cmp0.discrepancy
    steps = [entry(effect0, note0, d_before, d_prev, d_before,
                   paired_p(before_reps, reps0, d_before, d_prev))]
    chosen, notes = [effect0], [note0]
    current_cmp, current_reps = cmp0, reps0
    rejected: list = []
    remaining = [n for n in names if n != effect0.name]
    while remaining:
        given = a.with_given(chosen)
        c_given = given.compare(replicates=FINGERPRINT_REPLICATES)
        trials = []
        for name in remaining:
            cand = fit.fit_one(name, given, c_given)
            if cand.effect is None:
                continue
            try:
                after = b.compare(chosen + [cand.effect])
            except Exception:         # noqa: BLE001 - cannot run: not fitting
                continue
            trials.append((after.discrepancy, cand, after))
        if not trials:
            break
        step = None
        for rank, (d, cand, after) in enumerate(sorted(trials, key=lambda t: t[0])):
            effects = chosen + [cand.effect]
            if rank < JOINT:
                # fitted jointly: the chosen effects refitted given the candidate (a proxy
                # chosen earlier, e.g. one group for a shared flicker, can then give way),
                # kept unless the held-out part says the refit is worse
                joint = _backfit(a, effects)
                if joint != effects:
                    after_joint = b.compare(joint)
                    if after_joint.discrepancy < after.discrepancy:
                        effects, after = joint, after_joint
            d_new = after.discrepancy
            reps = b.replicate_discrepancies(after)
            p = paired_p(current_reps, reps, d_prev, d_new)
            added = (d_prev - d_new) / d_before if d_before > 0 else 0.0
            gains = _local_gains(first_cmp, current_cmp, after)
            if _counts(added, gains, p, d_new, d_prev, lambda: _confirmed(b, chosen, effects)):
                step = (cand, after, effects, reps, p)
                break
            if not rejected:
                rejected = [{'name': cand.name, 'added_reduction': added, 'p_value': p,
                             'note': cand.note}]
        if step is None:
            break
        cand, after, chosen, reps, p = step
        rejected = []
        notes.append(cand.note)
        remaining.remove(cand.name)
        current_cmp, current_reps = after, reps
        d_last, d_prev = d_prev, after.discrepancy
        steps.append(entry(chosen[-1], cand.note, d_before, d_prev, d_last, p))
        if log:
            log(f'compound: + {cand.name} -> {1 - d_prev / d_before:.2f}')
    # the parameters reported are the backfitted ones
    for s, e in zip(steps, chosen):
        s['parameters'] = entry(e, '', 1.0, 0.0, 0.0, 0.0)['parameters']
        s['sensors'] = list(e.sensors)
    return Compound(chosen, steps, d_before, current_cmp.discrepancy, current_cmp,
                    current_reps, rejected)


def _counts(added: float, gains: tuple, p: float, d_new: float, d_prev: float,
            confirmed) -> bool:
    """Does a step count: significant (``p < STEP_ALPHA``), lowering the discrepancy,
    and large enough by one of three measures (see ``_local_gains``); one large only by
    what is left must also be ``confirmed()``."""
    if p >= STEP_ALPHA or d_new >= d_prev:
        return False
    before_any, left = gains
    if added >= MIN_ADDED or before_any >= MIN_LOCAL:
        return True
    return left >= MIN_LEFT and confirmed()


def _confirmed(b: Target, chosen: list, effects: list) -> bool:
    """A step that counts only by what is left (``MIN_LEFT``) is checked again against a
    second simulated side (another simulator seed): once the remainder is small the
    simulator's own noise, which the paired bootstrap of the real data leaves out, can
    make a step of that size."""
    other = copy.copy(b)
    other.seed = b.seed + CONFIRM_SEED
    prev, new = other.compare(chosen), other.compare(effects)
    p = paired_p(other.replicate_discrepancies(prev), other.replicate_discrepancies(new),
                 prev.discrepancy, new.discrepancy)
    left = _local_gains(prev, prev, new)[1]
    return p < STEP_ALPHA and left >= MIN_LEFT and new.discrepancy < prev.discrepancy


def _local_gains(before, current, after) -> tuple:
    """The largest share a step removes of one part's own held-out discrepancy
    (stationary, closed-loop, or closed-loop noise statistics): (of that part before any
    effect, of what the chosen effects still leave of it).  A turn error acts only on
    closed-loop statistics, whose discrepancy can be small beside the stationary one's; and once
    the chosen effects leave a small remainder, an effect that explains much of that
    remainder is still a small share of the gap before any effect."""
    before_any = left = 0.0
    for part in ('stationary', 'closed_loop', 'closed_loop_noise', 'dropout'):
        d0, d1, d2 = (_part(c, part) for c in (before, current, after))
        if d0 > 0:
            before_any = max(before_any, (d1 - d2) / d0)
        if d1 > 0:
            left = max(left, (d1 - d2) / d1)
    return before_any, left


def _part(c, part: str) -> float:
    """The discrepancy of one protocol's statistics; the closed loop's noise statistics
    (``gap.closednoise``) count on their own: sensor effects act there beside a latency
    or turn error that dominates the closed loop's other statistics."""
    keep = np.array([_protocol(k.family) == part for k in c.keys], bool)
    return c.select(keep).discrepancy if keep.any() else 0.0


def _protocol(family: str) -> str:
    if family in dropout.FAMILIES:     # only a dropout moves them: they count on their own
        return 'dropout'
    if family in STATIONARY:
        return 'stationary'
    return 'closed_loop_noise' if family in closednoise.FAMILIES else 'closed_loop'


STATIONARY = {'level', 'spread', 'correlation', 'autocorrelation', 'kurtosis',
              'spread_vs_level', 'step_response', 'mode_share', 'granularity',
              'pileup'}


def _backfit(a: Target, chosen: list) -> list:
    """Refit each effect chosen before the last given all the others; keep a refit only
    where it lowers the fitting part's discrepancy (the held-out part is not used)."""
    out = list(chosen)
    for i in range(len(out) - 1):
        others = out[:i] + out[i + 1:]
        given = a.with_given(others)
        cand = fit.fit_one(out[i].name, given, given.compare(replicates=FINGERPRINT_REPLICATES))
        if cand.effect is None or cand.effect == out[i]:      # nothing to choose between
            continue
        if given.objective([cand.effect]) < given.objective([out[i]]):
            out[i] = cand.effect
    return out
