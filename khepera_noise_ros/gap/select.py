"""The compound diagnosis: forward selection of effects on held-out data, each fitted jointly
with those chosen (the rules: docs/diagnosis.md, "The compound")."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Container, Iterable, Sequence, TypeVar

import numpy as np

from ..effects import REGISTRY, Effect, from_dict
from ..effects.base import Array, Candidate
from .compare import Z_CAP, Comparison, chance, discrepancy, paired_p, reduction
from .families import PARTS, having
from .target import Target

MIN_REDUCTION = 0.25      # a single effect must remove this share of the gap (``diagnose``)
MIN_ADDED, MIN_LOCAL, MIN_LEFT = 0.005, 0.10, 0.50
STEP_ALPHA = 0.05
TIE = 0.10                # relative discrepancy within which the simpler effect is as good
FINGERPRINT_REPLICATES = 40
JOINT = 1                 # candidates per step refitted jointly with the chosen ones
CONFIRM_SEED = 5003       # offset of the second simulator seed
LOOP = ('sensor_latency', 'actuator_turn_error')
# what the recorded controller's actions produce: a model that predicts these worse on the
# held-out episodes is not kept, however well it fits the rest
LOOP_PARTS = ('closed_loop', 'closed_loop_noise')


def as_good(d_best: float, best_reps: Array, d_rival: float, rival_reps: Array,
            alpha: float) -> bool:
    """Does a rival explain the held-out data as well as the best: its discrepancy within
    ``TIE`` of the best's, or not beaten in ``1 - alpha`` of the paired replicates?"""
    return d_rival <= (1 + TIE) * d_best or float(np.mean(best_reps < rival_reps)) < 1 - alpha


def fit_one(name: str, target: Target, c: Comparison) -> Candidate:
    """The registered effect ``name`` fitted so that no failure escapes: an exception, or
    parameters its model cannot run, end as a candidate with no effect and the reason."""
    try:
        cand = REGISTRY[name].fit(target.evidence(c))
        if cand.effect is not None:
            runnable(cand.effect)
        return cand
    except Exception as exc:      # noqa: BLE001 - one candidate's failure is its own
        return Candidate(name, None, f'the fit failed: {type(exc).__name__}: {exc}')


def fit_given(name: str, target: Target, given: Sequence[Effect]) -> Candidate:
    """``fit_one`` of ``name`` on ``target`` with ``given`` always in the simulator (fitted
    jointly with them), against the fingerprint's comparison."""
    with_them = target.with_given(given)
    return fit_one(name, with_them, with_them.compare(replicates=FINGERPRINT_REPLICATES))


def runnable(effect: Effect) -> None:
    """Raise ValueError unless ``effect`` survives its dict form and a few finite steps."""
    effect = from_dict(effect.to_dict())
    channels = max([8] + [s + 1 for s in effect.sensors])
    step = effect.start(2, channels, np.random.default_rng(0))
    if effect.stage.value == 'turn':
        out = step(np.array([10.0, -10.0]))
    else:
        out = [step(np.full((channels, 2), 200.0)) for _ in range(3)][-1]
    if not np.all(np.isfinite(out)):
        raise ValueError(f'{effect.name} gives non-finite readings with {effect.to_dict()}')


def second_seed(b: Target, chosen: list[Effect],
                effects: list[Effect]) -> tuple[Target, Comparison, Comparison]:
    """(``b`` on another simulator seed, its comparisons with ``chosen`` and ``effects``): the
    paired bootstrap resamples the real data only; the simulator's noise can make a step."""
    other = b.with_seed(b.seed + CONFIRM_SEED)
    return other, other.compare(chosen), other.compare(effects)


@dataclass
class Compound:
    effects: list[Effect]
    steps: list[dict[str, Any]]
    discrepancy_before: float
    discrepancy_after: float
    comparison: Comparison
    rejected: list[dict[str, Any]] = field(default_factory=list)

    @property
    def reduction(self) -> float:
        return reduction(self.discrepancy_before, self.discrepancy_after)

    def to_json(self) -> dict[str, Any]:
        return {'chosen': self.steps, 'discrepancy_before': self.discrepancy_before,
                'discrepancy_after': self.discrepancy_after, 'heldout_reduction': self.reduction,
                'rejected': self.rejected, 'min_added': MIN_ADDED, 'min_left': MIN_LEFT,
                'step_alpha': STEP_ALPHA}


def entry(effect: Effect, note: str, d_before: float, d_after: float, d_prev: float,
          p: float, counted_by: str) -> dict[str, Any]:
    return {'name': effect.name, 'sensors': list(effect.sensors),
            'parameters': effect.parameters(), 'discrepancy_after': d_after,
            'added_reduction': (d_prev - d_after) / d_before if d_before > 0 else 0.0,
            'cumulative_reduction': reduction(d_before, d_after), 'p_value': p, 'note': note,
            'counted_by': counted_by}


@dataclass
class Step:
    cand: Candidate
    after: Comparison
    effects: list[Effect]
    reps: Array
    p: float
    rule: str


class Selection:
    """Forward selection on fitting target ``a``, scored on held-out target ``b``."""

    def __init__(self, a: Target, b: Target, first: Comparison, d_before: float):
        self.a, self.b, self.first, self.d_before = a, b, first, d_before
        self.vetoed: dict[str, str] = {}     # effect -> the closed-loop part it predicts worse

    def run(self, best: tuple[Effect, str, Comparison, Array], names: Sequence[str],
            before_reps: Array) -> Compound:
        effect0, note0, cmp0, reps0 = best
        d_prev = cmp0.discrepancy
        steps = [entry(effect0, note0, self.d_before, d_prev, self.d_before,
                       paired_p(before_reps, reps0, self.d_before, d_prev), 'top_effect')]
        chosen, current, current_reps = [effect0], cmp0, reps0
        rejected: list[dict[str, Any]] = []
        remaining = [n for n in names if n != effect0.name]
        while remaining:
            given = self.a.with_given(chosen)
            c_given = given.compare(replicates=FINGERPRINT_REPLICATES)
            trials = []
            for name in remaining:
                cand = fit_one(name, given, c_given)
                after = None if cand.effect is None else self._held_out(chosen + [cand.effect])
                if (after is None or after.discrepancy >= d_prev) and \
                        name in LOOP and any(e.name in LOOP and e.name != name for e in chosen) \
                        and _part(current, 'closed_loop') > _part_chance(current, 'closed_loop'):
                    cand, after = self._loop_pair(chosen, name, cand, after)
                if after is not None:
                    trials.append((after.discrepancy, cand, after))
            trials.sort(key=lambda t: t[0])
            for rank, (_, cand, after) in enumerate(trials):
                effects = _with(chosen, cand)
                if rank < JOINT or _confounded(current, after):
                    joint = self.backfit(effects)       # a proxy chosen earlier can give way
                    if joint != effects:
                        after_joint = self.b.compare(joint)
                        if after_joint.discrepancy < after.discrepancy:
                            effects, after = joint, after_joint
                rule, reps, p, added = self.judge(current, current_reps, chosen, effects, after,
                                                  d_prev)
                if rule:
                    step = Step(cand, after, effects, reps, p, rule)
                    break
                rejected.append({'name': cand.name, 'added_reduction': added, 'p_value': p,
                                 'note': cand.note, 'parts': self._detail(current, after),
                                 'closed_loop_worse': self.vetoed.get(cand.name, '')})
            else:                # no trial counts (or none could run): the selection ends
                break
            step = self._simplest(step, trials, current, current_reps, chosen, d_prev)
            rejected = []
            remaining.remove(step.cand.name)
            chosen, current, current_reps = step.effects, step.after, step.reps
            d_last, d_prev = d_prev, step.after.discrepancy
            steps.append(entry(chosen[-1], step.cand.note, self.d_before, d_prev, d_last, step.p,
                               step.rule))
        for s, e in zip(steps, chosen):            # the parameters reported are the backfitted
            s['parameters'], s['sensors'] = e.parameters(), list(e.sensors)
        return Compound(chosen, steps, self.d_before, current.discrepancy, current, rejected)

    def _loop_pair(self, chosen: list[Effect], name: str, cand: Candidate,
                   after: Comparison | None) -> tuple[Candidate, Comparison | None]:
        """A latency and a turn error both move the readings' response to a turn, so the one
        chosen first takes the other's share: the candidate fitted without it and it refitted
        given the candidate, if that beats the plain fit."""
        alone = fit_given(name, self.a, [e for e in chosen if e.name not in LOOP])
        if alone.effect is None:
            return cand, after
        both = self.backfit(chosen + [alone.effect], LOOP)
        paired = self._held_out(both)
        if paired is None or (after is not None and after.discrepancy <= paired.discrepancy):
            return cand, after
        note = alone.note + ' (fitted with the loop effect refitted)'
        return Candidate(name, alone.effect, note, given=both[:-1]), paired

    def _held_out(self, effects: list[Effect]) -> Comparison | None:
        try:
            return self.b.compare(effects)
        except Exception:         # noqa: BLE001 - cannot run: not fitting
            return None

    def backfit(self, chosen: list[Effect], names: Container[str] | None = None) -> list[Effect]:
        """Each effect chosen before the last (of ``names``, if given) refitted given all the
        others."""
        out = list(chosen)
        for i in range(len(out) - 1):
            if names is None or out[i].name in names:
                out[i] = self.refit(out[i], out[:i] + out[i + 1:])
        return out

    def refit(self, effect: Effect, others: list[Effect]) -> Effect:
        """``effect`` refitted given ``others``, if that lowers the fitting part's objective."""
        cand = fit_given(effect.name, self.a, others)
        if cand.effect is None or cand.effect == effect:
            return effect
        given = self.a.with_given(others)
        better = given.objective([cand.effect]) < given.objective([effect])
        return cand.effect if better else effect

    def judge(self, current: Comparison, current_reps: Array, chosen: list[Effect],
              effects: list[Effect], after: Comparison,
              d_prev: float) -> tuple[str, Array, float, float]:
        """(the rule the step counts by or '', its replicate discrepancies, p, added share)."""
        b, d_new, first = self.b, after.discrepancy, self.first
        reps = b.replicate_discrepancies(after)
        p = paired_p(current_reps, reps, d_prev, d_new)
        added = (d_prev - d_new) / self.d_before if self.d_before > 0 else 0.0

        def confirmed(holds: Callable[[Target, Comparison, Comparison], bool]) -> bool:
            """On a second simulator seed too the step is significant, lowers the
            discrepancy and ``holds``."""
            other, prev, new = second_seed(b, chosen, effects)
            p2 = paired_p(other.replicate_discrepancies(prev), other.replicate_discrepancies(new),
                          prev.discrepancy, new.discrepancy)
            return p2 < STEP_ALPHA and new.discrepancy < prev.discrepancy and \
                holds(other, prev, new)
        rule = ''
        if p < STEP_ALPHA and d_new < d_prev:
            before_any, left = _local_gains(first, current, after)
            if added >= MIN_ADDED:
                rule = 'min_added'
            elif before_any >= MIN_LOCAL:
                rule = 'min_local'
            elif left >= MIN_LEFT and confirmed(
                    lambda o, pv, nw: _local_gains(pv, pv, nw)[1] >= MIN_LEFT):
                rule = 'min_left'
            elif d_prev - d_new >= MIN_LOCAL * d_prev and \
                    _family_gain(b, first, current, after) >= MIN_LOCAL and \
                    confirmed(lambda o, pv, nw: _family_gain(o, first, pv, nw) >= MIN_LOCAL):
                rule = 'family'
        # only a slow wander widens the levels' error bars without bringing anything
        # closer; an effect adding fast noise rightly widens the spreads' error bars
        if rule and effects[-1].name == 'temporal_drift' and not _closer(current, after):
            rule = ''
        if rule and (worse := loop_worse(b, chosen, effects, current, after)):
            rule, self.vetoed[effects[-1].name] = '', worse
        return rule, reps, p, added

    def _simplest(self, step: Step, trials: list[tuple[float, Candidate, Comparison]],
                  current: Comparison, current_reps: Array, chosen: list[Effect],
                  d_prev: float) -> Step:
        """The simplest candidate that also counts and explains the held-out data as well
        (``as_good``), else the step's: a spread law of exponent 0 shared by a few sensors
        is a group of correlated noise, and by the data alone the group would lose to the
        law's extra parameter by chance half the time."""
        for d, rival, rival_after in simpler(trials, step.cand.name, lambda t: t[1].name,
                                             lambda t: t[0]):
            if not as_good(step.after.discrepancy, step.reps, d,
                           self.b.replicate_discrepancies(rival_after), STEP_ALPHA):
                continue
            effects = _with(chosen, rival)
            rule, reps, p, _ = self.judge(current, current_reps, chosen, effects, rival_after,
                                          d_prev)
            if rule:
                return Step(rival, rival_after, effects, reps, p, rule + ', simpler')
        return step

    def _detail(self, current: Comparison, after: Comparison) -> dict[str, Any]:
        """Per part, what a rejected step did: its shares and the paired p on the part."""
        out = {}
        for part in PARTS:
            d0, d1, d2 = (_part(c, part) for c in (self.first, current, after))
            if d0 <= 0 and d1 <= 0:
                continue
            reps = [self.b.replicate_discrepancies(c.part(part)) for c in (current, after)]
            out[part] = {'before_any': round(d0, 2), 'left': round(d1, 2), 'after': round(d2, 2),
                         'gain_before_any': round((d1 - d2) / d0, 4) if d0 > 0 else 0.0,
                         'gain_left': round((d1 - d2) / d1, 4) if d1 > 0 else 0.0,
                         'p': round(paired_p(reps[0], reps[1], d1, d2), 3)}
        return out


T = TypeVar('T')


def simpler(rivals: Iterable[T], than: str, name: Callable[[T], str],
            worse: Callable[[T], float]) -> list[T]:
    """The parsimony rule's order: the ``rivals`` with fewer free parameters than the effect
    ``than``, fewest first, then by ``worse``."""
    return sorted((r for r in rivals if REGISTRY[name(r)].free < REGISTRY[than].free),
                  key=lambda r: (REGISTRY[name(r)].free, worse(r)))


def loop_worse(b: Target, chosen: list[Effect], effects: list[Effect], current: Comparison,
               after: Comparison) -> str:
    """The part of ``LOOP_PARTS`` that ``effects`` (``after``) predict significantly worse
    than ``chosen`` (``current``) on the held-out episodes, on a second seed too; or ''."""
    first = _worse(b, current, after)
    if not first:
        return ''
    again = _worse(*second_seed(b, chosen, effects))
    return next((p for p in first if p in again), '')


def _worse(t: Target, c: Comparison, a: Comparison) -> list[str]:
    """The ``LOOP_PARTS`` that ``a`` predicts significantly worse than ``c`` (one-sided)."""
    out = []
    for part in LOOP_PARTS:
        cp, ap = c.part(part), a.part(part)
        if cp.keys and ap.discrepancy > cp.discrepancy and paired_p(
                t.replicate_discrepancies(ap), t.replicate_discrepancies(cp),
                ap.discrepancy, cp.discrepancy) < STEP_ALPHA:
            out.append(part)
    return out


def _with(chosen: list[Effect], cand: Candidate) -> list[Effect]:
    assert cand.effect is not None
    return list(chosen if cand.given is None else cand.given) + [cand.effect]


def _part(c: Comparison, part: str) -> float:
    return discrepancy(c.z[c.parts == part])


def _part_chance(c: Comparison, part: str) -> float:
    return chance(int(np.sum(c.parts == part)))


def _confounded(current: Comparison, after: Comparison) -> bool:
    """Does a step bring one part well closer while another moves away?  The effects
    chosen before it, fitted without it, took part of its share: worth refitting them."""
    d = [(_part(current, p), _part(after, p), _part_chance(current, p)) for p in PARTS]
    return any(d1 > limit and d1 - d2 >= MIN_LOCAL * d1 for d1, d2, limit in d) and \
        any(d2 > d1 and d2 > limit for d1, d2, limit in d)


def _local_gains(before: Comparison, current: Comparison,
                 after: Comparison) -> tuple[float, float]:
    """The largest share a step removes of one part's held-out discrepancy: (of the part
    before any effect, of what the chosen effects leave of it)."""
    d = [[_part(c, p) for c in (before, current, after)] + [_part_chance(current, p)]
         for p in PARTS]
    return max([0.0] + [(d1 - d2) / d0 for d0, d1, d2, _ in d if d0 > 0]), \
        max([0.0] + [(d1 - d2) / d1 for _, d1, d2, limit in d if d1 > limit])


def _family_gain(b: Target, before: Comparison, current: Comparison, after: Comparison) -> float:
    """The largest share a step removes of one family's held-out discrepancy before any
    effect, where the fall is significant on the family's replicates (a dominant effect
    makes most of a part; a drift beside it acts on other families)."""
    best = 0.0
    for fam in sorted({k.family for k in before.keys}):
        d0, d1, d2 = (c.of(fam).discrepancy for c in (before, current, after))
        if d0 <= 0 or d2 >= d1 or (d1 - d2) / d0 < MIN_LOCAL or \
                d1 <= chance(sum(k.family == fam for k in current.keys)):
            continue
        if paired_p(b.replicate_discrepancies(current.of(fam)),
                    b.replicate_discrepancies(after.of(fam)), d1, d2) < STEP_ALPHA:
            best = max(best, (d1 - d2) / d0)
    return best


def _closer(current: Comparison, after: Comparison) -> bool:
    """Does the step bring the simulated statistics closer at the error bars before it: all
    of them, or those other than the ones a wander widens?"""
    index = current.index
    rows = [(i, index[k]) for i, k in enumerate(after.keys) if k in index]
    if not rows:
        return True
    ai, ci = (np.array(r, np.int64) for r in zip(*rows))
    with np.errstate(divide='ignore', invalid='ignore'):
        z = (after.real[ai] - after.sim[ai]) / current.se[ci]
    z = np.clip(np.nan_to_num(z, nan=0.0), -Z_CAP, Z_CAP)
    if discrepancy(z) < discrepancy(current.z[ci]):
        return True
    other = np.array([current.keys[i].family not in having('widened') for i in ci], bool)
    return discrepancy(z[other]) < discrepancy(current.z[ci][other])
