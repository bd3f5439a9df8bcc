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
same resampled real data against both simulators), or, failing that test, in those of
the one part it acts on (``partstep``).  With the best candidate
the effects chosen earlier are refitted given the others (one backfitting
pass), each refit kept only where it lowers the *fitting* part's discrepancy,
the refitted set only where the held-out one does not rise; so too with any
candidate whose step is confounded (one part closer, another away).  A latency or
turn error beside the other one chosen is also fitted without it, the chosen one
refitted given it (``_loop_pair``).  Selection stops when no candidate adds a
significant share.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np

from . import effects as fx
from . import closednoise, dropout, fit, loopvalues, partstep
from .partstep import paired_p  # noqa: F401 - compound.paired_p, as before
from .target import Target
from .where import Z_CAP, discrepancy

MIN_ADDED = 0.005         # share of the discrepancy before any effect a step must remove
MIN_LOCAL = 0.10          # ... or this share of one protocol's own discrepancy (see below)
MIN_LEFT = 0.50           # ... or of what the chosen effects leave of one protocol's part
STEP_ALPHA = 0.05         # one-sided, paired bootstrap
FINGERPRINT_REPLICATES = 40
JOINT = 1                 # candidates per step refitted jointly with the chosen ones
# Free parameters of each effect's model, beyond its location: when two effects explain
# the held-out data equally well, the one with fewer wins (correlated noise is the
# paper's model; intensity-dependent noise with a flat exponent is the same thing).
# ``diagnose`` ranks single effects by it, each compound step too.
TIE = 0.10
PARAMETERS = {'sensor_latency': 1, 'correlated_noise': 1, 'actuator_turn_error': 2,
              'intensity_dependent_noise': 2, 'temporal_drift': 3,
              'saturation_quantization': 3, 'sensor_gain_offset': 4}
CONFIRM_SEED = 5003       # offset of the second simulator seed a MIN_LEFT step is checked on
# Discrepancy of one statistic with no gap at all, z ~ N(0, 1): mean and variance of
# max(|z| - 2, 0)^2 (``where.discrepancy``); what is left of a part is worked on by
# the MIN_LEFT and family rules only above the chance mean + CHANCE_SDS sds.
CHANCE_MEAN, CHANCE_VAR, CHANCE_SDS = 0.011537, 0.012703, 3.0
WIDENED = ('level', 'spread')   # statistics whose error bars a drift's wander widens
PART = partstep.Rule(STEP_ALPHA, MIN_LOCAL, MIN_LEFT, CONFIRM_SEED)
PART_RULE = True          # a step may count by one part's own replicates (``partstep``)


@dataclass
class Compound:
    effects: list                       # fitted effects, in the order chosen
    steps: list                         # one dict per chosen effect (diagnosis.json)
    discrepancy_before: float
    discrepancy_after: float
    comparison: object = None           # held-out comparison with every chosen effect
    replicates: np.ndarray | None = None
    rejected: list = field(default_factory=list)   # the candidates of the last step, none counted

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
    steps[0]['counted_by'] = 'top_effect'
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
            after = None
            if cand.effect is not None:
                try:
                    after = b.compare(chosen + [cand.effect])
                except Exception:         # noqa: BLE001 - cannot run: not fitting
                    cand = fit.Candidate(name, None, 'cannot run')
            if (cand.effect is None or after.discrepancy >= d_prev) and \
                    _other_loop(chosen, name) and _loop_left(current_cmp):
                cand, after = _loop_pair(a, b, chosen, name, cand, after)
            if cand.effect is not None:
                trials.append((after.discrepancy, cand, after))
        if not trials:
            break
        step = None
        trials.sort(key=lambda t: t[0])
        for rank, (d, cand, after) in enumerate(trials):
            effects = _with(chosen, cand)
            if rank < JOINT or _confounded(current_cmp, after):
                # fitted jointly: the chosen effects refitted given the candidate (a proxy
                # chosen earlier, e.g. one group for a shared flicker, can then give way),
                # kept unless the held-out part says the refit is worse
                joint = _backfit(a, effects)
                if joint != effects:
                    after_joint = b.compare(joint)
                    if after_joint.discrepancy < after.discrepancy:
                        effects, after = joint, after_joint
            judged = _judge(b, first_cmp, current_cmp, current_reps, chosen, effects, after,
                            d_before, d_prev)
            if judged[0]:
                step = (cand, after, effects, judged[1], judged[2], judged[0])
                break
            rejected.append({'name': cand.name, 'added_reduction': judged[3],
                             'p_value': judged[2], 'note': cand.note,
                             'parts': _part_detail(b, first_cmp, current_cmp, after)})
        if step is None:
            break
        step = _simplest(step, trials, b, first_cmp, current_cmp, current_reps, chosen,
                         d_before, d_prev)
        cand, after, chosen, reps, p, rule = step
        rejected = []
        notes.append(cand.note)
        remaining.remove(cand.name)
        current_cmp, current_reps = after, reps
        d_last, d_prev = d_prev, after.discrepancy
        steps.append(entry(chosen[-1], cand.note, d_before, d_prev, d_last, p))
        steps[-1]['counted_by'] = rule
        if log:
            log(f'compound: + {cand.name} -> {1 - d_prev / d_before:.2f}')
    # the parameters reported are the backfitted ones
    for s, e in zip(steps, chosen):
        s['parameters'] = entry(e, '', 1.0, 0.0, 0.0, 0.0)['parameters']
        s['sensors'] = list(e.sensors)
    return Compound(chosen, steps, d_before, current_cmp.discrepancy, current_cmp,
                    current_reps, rejected)


LOOP = ('sensor_latency', 'actuator_turn_error')


def _other_loop(chosen: list, name: str) -> bool:
    """Is ``name`` an effect on the loop while another one is chosen?"""
    return name in LOOP and any(e.name in LOOP and e.name != name for e in chosen)


def _loop_left(c) -> bool:
    """Is more of the closed loop's own discrepancy left than chance gives?"""
    return _part(c, 'closed_loop') > _part_chance(c, 'closed_loop')


def _loop_pair(a: Target, b: Target, chosen: list, name: str, cand, after) -> tuple:
    """A latency and a turn error both move the readings' response to a turn: the one
    chosen first, fitted alone, takes the other's share, and given it the other shows no
    fingerprint or fits the wrong way.  The candidate is fitted given the chosen effects
    other than the loop one, the loop one then refitted given it; (candidate, held-out
    comparison with the pair), the better of that and the plain fit."""
    base = [e for e in chosen if e.name not in LOOP]
    given = a.with_given(base)
    alone = fit.fit_one(name, given, given.compare(replicates=FINGERPRINT_REPLICATES))
    if alone.effect is None:
        return cand, after
    out = list(chosen)
    for i, e in enumerate(out):
        if e.name in LOOP:
            out[i] = _refit(a, e, out[:i] + out[i + 1:] + [alone.effect])
    try:
        paired = b.compare(out + [alone.effect])
    except Exception:         # noqa: BLE001 - cannot run: not fitting
        return cand, after
    if after is not None and after.discrepancy <= paired.discrepancy:
        return cand, after
    # the chosen loop effect refitted travels with the candidate (``_backfit`` keeps it
    # only where it fits the fitting part better)
    return fit.Candidate(name, alone.effect,
                         alone.note + ' (fitted with the loop effect refitted)',
                         given=out), paired


def _with(chosen: list, cand) -> list:
    """The chosen effects (as refitted with the candidate, ``_loop_pair``) and it."""
    return list(chosen if cand.given is None else cand.given) + [cand.effect]


def _confounded(current, after) -> bool:
    """Does a step bring one part well closer (a tenth of what is left, above chance)
    while another moves away?  The effects chosen before it, fitted without it, took
    part of its share: it is worth fitting them again given it."""
    closer = away = False
    for part in PARTS:
        d1, d2 = _part(current, part), _part(after, part)
        chance = _part_chance(current, part)
        closer |= d1 > chance and d1 - d2 >= MIN_LOCAL * d1
        away |= d2 > d1 and d2 > chance
    return closer and away


def _judge(b: Target, first_cmp, current_cmp, current_reps, chosen: list, effects: list,
           after, d_before: float, d_prev: float) -> tuple:
    """(the rule it counts by or '', replicate discrepancies, p, added share) of the
    step from ``chosen`` to ``effects`` (held-out comparison ``after``)."""
    d_new = after.discrepancy
    reps = b.replicate_discrepancies(after)
    p = paired_p(current_reps, reps, d_prev, d_new)
    added = (d_prev - d_new) / d_before if d_before > 0 else 0.0
    gains = _local_gains(first_cmp, current_cmp, after)
    family = _family_gain(b, first_cmp, current_cmp, after)
    counts = _counts(added, gains, p, d_new, d_prev, lambda: _confirmed(b, chosen, effects),
                     family, lambda: _family_confirmed(b, first_cmp, chosen, effects))
    if not counts and PART_RULE:    # a small part's share, judged on its own replicates
        counts = partstep.counts(b, _split, _chance, first_cmp, current_cmp, after, chosen,
                                 effects, PART)
    # only a slow wander widens the levels' error bars without bringing anything closer
    # (the level inflation of ``Target``); an effect that adds fast noise rightly widens
    # the spreads' error bars, and judged at the old ones it loses its share
    if counts and effects[-1].name == fx.TemporalDrift.name and \
            not _closer(current_cmp, after):
        counts = ''
    return counts, reps, p, added


def _closer(current, after) -> bool:
    """Does the step bring the simulated statistics closer to the real ones, judged at
    the error bars before it: all of them, or those other than the levels and spreads?
    An effect that adds variance between and within simulated runs (a drift) widens the
    error bars of the levels and spreads, which lowers their z however far off they
    are; a drift beside a calibration fitted a little off then lowers the held-out
    discrepancy without matching anything.  A real drift also matches the time
    structure (autocorrelation, correlation), while its wander moves the simulated
    levels and spreads about."""
    index = {k: i for i, k in enumerate(current.keys)}
    rows = [(i, index[k]) for i, k in enumerate(after.keys) if k in index]
    if not rows:
        return True
    ai, ci = (np.array(r, np.int64) for r in zip(*rows))
    with np.errstate(divide='ignore', invalid='ignore'):
        z = (after.real[ai] - after.sim[ai]) / current.se[ci]
    z = np.clip(np.nan_to_num(z, nan=0.0), -Z_CAP, Z_CAP)
    if discrepancy(z) < discrepancy(current.z[ci]):
        return True
    other = np.array([current.keys[i].family not in WIDENED for i in ci], bool)
    return discrepancy(z[other]) < discrepancy(current.z[ci][other])


def _simplest(step: tuple, trials: list, b: Target, first_cmp, current_cmp, current_reps,
              chosen: list, d_before: float, d_prev: float) -> tuple:
    """The step's candidate, or a simpler one (fewer free parameters, the single effects'
    parsimony rule of ``diagnose``) that also counts and explains the held-out data as
    well: its discrepancy within ``TIE`` of the step's, or not beaten in ``1 - alpha``
    of the paired replicates.  A spread law of exponent 0 shared by a few sensors is a
    group of correlated noise; told apart by the data alone the group would lose to the
    law's one extra parameter by chance half the time."""
    cand, after, _, reps, _, _ = step
    rivals = sorted((t for t in trials if t[1] is not cand
                     and PARAMETERS.get(t[1].name, 99) < PARAMETERS.get(cand.name, 99)),
                    key=lambda t: (PARAMETERS.get(t[1].name, 99), t[0]))
    for d, rival, rival_after in rivals:
        if d > (1 + TIE) * after.discrepancy:
            rival_reps = b.replicate_discrepancies(rival_after)
            if np.mean(reps < rival_reps) >= 1 - STEP_ALPHA:
                continue
        effects = _with(chosen, rival)
        rule, rival_reps, p, _ = _judge(b, first_cmp, current_cmp, current_reps, chosen,
                                        effects, rival_after, d_before, d_prev)
        if rule:
            return rival, rival_after, effects, rival_reps, p, rule + ', simpler'
    return step


def _counts(added: float, gains: tuple, p: float, d_new: float, d_prev: float,
            confirmed, family: float = 0.0, family_confirmed=None) -> str:
    """Which rule a step counts by ('' for none): significant (``p < STEP_ALPHA``),
    lowering the discrepancy, and large enough by one of three measures (see
    ``_local_gains``); one large only by what is left must also be ``confirmed()``.  A
    step that does not count so, but removes ``MIN_LOCAL`` of one statistic family's own
    discrepancy (``_family_gain``, significant on its own replicates) and of all that is
    left, counts when ``family_confirmed()``."""
    if p >= STEP_ALPHA or d_new >= d_prev:
        return ''
    before_any, left = gains
    if added >= MIN_ADDED:
        return 'min_added'
    if before_any >= MIN_LOCAL:
        return 'min_local'
    if left >= MIN_LEFT and confirmed():
        return 'min_left'
    if family >= MIN_LOCAL and d_prev - d_new >= MIN_LOCAL * d_prev and \
            family_confirmed is not None and family_confirmed():
        return 'family'
    return ''


def _confirmed(b: Target, chosen: list, effects: list) -> bool:
    """A step that counts only by what is left (``MIN_LEFT``) is checked again against a
    second simulated side (another simulator seed): once the remainder is small the
    simulator's own noise, which the paired bootstrap of the real data leaves out, can
    make a step of that size."""
    _, prev, new = _second_seed(b, chosen, effects)
    return new is not None and _local_gains(prev, prev, new)[1] >= MIN_LEFT


def _second_seed(b: Target, chosen: list, effects: list) -> tuple:
    """(the target on another simulator seed, its comparisons with ``chosen`` and with
    ``effects``); the latter None unless the step lowers the discrepancy there too, in
    ``1 - alpha`` of the paired replicates."""
    other = copy.copy(b)
    other.seed = b.seed + CONFIRM_SEED
    prev, new = other.compare(chosen), other.compare(effects)
    p = paired_p(other.replicate_discrepancies(prev), other.replicate_discrepancies(new),
                 prev.discrepancy, new.discrepancy)
    ok = p < STEP_ALPHA and new.discrepancy < prev.discrepancy
    return other, prev, new if ok else None


def _local_gains(before, current, after) -> tuple:
    """The largest share a step removes of one part's own held-out discrepancy
    (stationary, closed-loop, or closed-loop noise statistics): (of that part before any
    effect, of what the chosen effects still leave of it).  A turn error acts only on
    closed-loop statistics, whose discrepancy can be small beside the stationary one's; and once
    the chosen effects leave a small remainder, an effect that explains much of that
    remainder is still a small share of the gap before any effect."""
    before_any = left = 0.0
    for part in PARTS:
        d0, d1, d2 = (_part(c, part) for c in (before, current, after))
        if d0 > 0:
            before_any = max(before_any, (d1 - d2) / d0)
        if d1 > _part_chance(current, part):
            left = max(left, (d1 - d2) / d1)
    return before_any, left


def _part_detail(b: Target, before, current, after) -> dict:
    """Per part, what a step did (for ``rejected``): its share of the part before any
    effect and of what is left, and the paired p on the part's own replicates."""
    out = {}
    for part in PARTS:
        d0, d1, d2 = (_part(c, part) for c in (before, current, after))
        if d0 <= 0 and d1 <= 0:
            continue
        reps = [b.replicate_discrepancies(c.select(_protocols(c) == part))
                for c in (current, after)]
        out[part] = {'before_any': round(d0, 2), 'left': round(d1, 2), 'after': round(d2, 2),
                     'gain_before_any': round((d1 - d2) / d0, 4) if d0 > 0 else 0.0,
                     'gain_left': round((d1 - d2) / d1, 4) if d1 > 0 else 0.0,
                     'p': round(paired_p(reps[0], reps[1], d1, d2), 3)}
    return out


def _chance(n: int) -> float:
    """The discrepancy ``n`` statistics reach by chance with no gap left (mean + 3 sd):
    once a part's remainder is below it, halving it is fitting the noise (a part with
    few statistics left at 0.5 halves by chance)."""
    return n * CHANCE_MEAN + CHANCE_SDS * np.sqrt(n * CHANCE_VAR)


def _family_gain(b: Target, before, current, after) -> float:
    """The largest share a step removes of one statistic family's own held-out
    discrepancy before any effect, among families where the step's fall is significant
    on the family's own paired replicates.  A dominant effect (a latency's step
    responses, a turn error's turn responses) makes most of a protocol's discrepancy;
    a drift or a calibration beside it acts on other families (levels,
    autocorrelation), whose share of the protocol's discrepancy is then small."""
    best = 0.0
    for fam in sorted({k.family for k in before.keys}):
        d0, d1, d2 = (_family(c, fam) for c in (before, current, after))
        if d0 <= 0 or d2 >= d1 or (d1 - d2) / d0 < MIN_LOCAL or \
                d1 <= _chance(sum(k.family == fam for k in current.keys)):
            continue
        p = paired_p(_family_reps(b, current, fam), _family_reps(b, after, fam), d1, d2)
        if p < STEP_ALPHA:
            best = max(best, (d1 - d2) / d0)
    return best


def _family_confirmed(b: Target, before, chosen: list, effects: list) -> bool:
    """A step that counts only by one family's share is checked again against a second
    simulated side (another simulator seed), as ``_confirmed`` does."""
    other, prev, new = _second_seed(b, chosen, effects)
    return new is not None and _family_gain(other, before, prev, new) >= MIN_LOCAL


def _family(c, family: str) -> float:
    return _discrepancy_of(c, lambda fam: fam == family)


def _family_reps(b: Target, c, family: str) -> np.ndarray:
    return b.replicate_discrepancies(c.select([k.family == family for k in c.keys]))


def _part(c, part: str) -> float:
    """The discrepancy of one protocol's statistics; the closed loop's noise statistics
    (``gap.closednoise``) count on their own: sensor effects act there beside a latency
    or turn error that dominates the closed loop's other statistics."""
    keep = _protocols(c) == part
    return discrepancy(c.z[keep]) if keep.any() else 0.0


def _protocols(c) -> np.ndarray:
    """Each statistic's part (``_protocol``) of comparison ``c``, worked out once."""
    of = c.__dict__.get('_protocols')
    if of is None:
        of = c.__dict__['_protocols'] = np.array([_protocol(k.family) for k in c.keys])
    return of


def _split(c) -> dict:
    """Each part's statistics of comparison ``c`` (parts with none left out)."""
    of = _protocols(c)
    return {p: c.select(of == p) for p in PARTS if (of == p).any()}


def _part_chance(c, part: str) -> float:
    """``_chance`` of one part's statistics in comparison ``c``."""
    return _chance(int(np.sum(_protocols(c) == part)))


def _discrepancy_of(c, wanted) -> float:
    """The discrepancy of the statistics of ``c`` whose family is ``wanted`` (0 if none)."""
    keep = np.array([wanted(k.family) for k in c.keys], bool)
    return c.select(keep).discrepancy if keep.any() else 0.0


def _protocol(family: str) -> str:
    if family in dropout.FAMILIES:     # only a dropout moves them: they count on their own
        return 'dropout'
    if family in loopvalues.FAMILIES:  # only a limit or a lattice moves them
        return 'loop_values'
    if family in STATIONARY:
        return 'stationary'
    return 'closed_loop_noise' if family in closednoise.FAMILIES else 'closed_loop'


PARTS = ('stationary', 'closed_loop', 'closed_loop_noise', 'dropout',
         'loop_values')   # see ``_protocol``
STATIONARY = {'level', 'spread', 'correlation', 'autocorrelation', 'own_autocorrelation',
              'kurtosis', 'spread_vs_level', 'step_response', 'mode_share', 'granularity',
              'pileup'}


def _backfit(a: Target, chosen: list) -> list:
    """Refit each effect chosen before the last given all the others; keep a refit only
    where it lowers the fitting part's discrepancy (the held-out part is not used)."""
    out = list(chosen)
    for i in range(len(out) - 1):
        out[i] = _refit(a, out[i], out[:i] + out[i + 1:])
    return out


def _refit(a: Target, effect, others: list):
    """``effect`` refitted given ``others``, kept only where it lowers the fitting part's
    discrepancy; else ``effect``."""
    given = a.with_given(others)
    cand = fit.fit_one(effect.name, given, given.compare(replicates=FINGERPRINT_REPLICATES))
    if cand.effect is None or cand.effect == effect:      # nothing to choose between
        return effect
    return cand.effect if given.objective([cand.effect]) < given.objective([effect]) \
        else effect
