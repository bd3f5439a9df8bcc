"""The diagnosis: where the gap lies, which unmodelled effect causes it, how far it shrinks.

1. Where: every statistic of the real recordings against the simulator's replay
   of the same protocol (``gap.where``), ranked by standardised difference.
2. Which: the recordings are split (``gap.split``); each effect of the
   vocabulary is located and fitted on one part (``gap.fit``), added to the
   simulator, and scored on the other part by the fraction of the discrepancy
   it removes.  The effects are ranked by that held-out reduction.
3. How far: the discrepancy before and after the top effect on held-out data,
   with a bootstrap interval; for closed-loop data, optionally the transfer
   experiment (``gap.transfer``).

The verdict is ``none`` when no statistic differs significantly (the gap is
not significant) or when no effect removes a significant share of it.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..recording import Recording
from . import effects as fx
from . import allan, compound, fit, remainder, replay, rounding, split, transfer
from .compound import PARAMETERS, TIE   # the parsimony rule's table, shared with the steps
from .simconfig import SimConfig
from .target import Target
from .where import ALPHA, Comparison, entries, localise

FORMAT = 'khepera-noise-diagnosis/1'
MIN_REDUCTION = 0.25       # an explanation must remove at least this share of the gap
REDUCTION_ALPHA = 0.05     # ... and do so in 95% of the bootstrap replicates
MIN_SAMPLES = 40


@dataclass
class Options:
    config: SimConfig = field(default_factory=SimConfig)
    seed: int = 0
    base: str = 'auto'
    held_out: tuple = ()          # conditions held out of the fit; () = alternate episodes
    alpha: float = ALPHA                        # family-wise, for "is there a gap"
    reduction_alpha: float = REDUCTION_ALPHA    # one-sided, for "does the effect shrink it"
    min_reduction: float = MIN_REDUCTION
    replicates: int = 200
    effects: tuple = fx.NAMES
    where_limit: int = 40
    compound: bool = True         # forward selection of a set of effects after the best one
    remainder: bool = True        # describe what is left and fit the empirical model
    rounding: bool = True         # choose where the simulator rounds from the value lattice


@dataclass
class Diagnosis:
    where: list
    localisation: dict
    effects: list
    top_effect: str
    fitted: object | None            # the top effect, ready for the simulator
    gap_significant: bool
    notes: list
    full: Comparison                 # real against simulated, all data
    held_out_before: Comparison | None = None
    held_out_after: Comparison | None = None
    transfer: dict | None = None
    inputs: list = field(default_factory=list)
    combined: dict | None = None     # the chosen effects together (the compound's summary)
    compound: compound.Compound | None = None
    remainder: dict | None = None    # what the named effects leave (held out), empirical model
    empirical: object | None = None  # the empirical model, when it brings the simulator closer
    allan: dict | None = None        # Allan deviation profiles, real and simulated (gap.allan)
    rounding: dict | None = None     # where the simulator rounds, as chosen (gap.rounding)

    @property
    def fitted_effects(self) -> list:
        """What fitted_params.yaml loads: the compound set, else the top effect."""
        if self.compound is not None:
            return list(self.compound.effects)
        return [] if self.fitted is None else [self.fitted]

    def simulator(self, config: SimConfig) -> SimConfig:
        """``config`` with the rounding the diagnosis chose (what fitted_params.yaml has)."""
        if not self.rounding:
            return config
        return rounding.with_rounding(config, self.rounding['rounding'])

    def to_json(self) -> dict:
        """diagnosis.json: the fixed keys of format 1 plus this project's additions.

        Returns:
            A dict of plain JSON values (``format``, ``where``, ``effects``,
            ``top_effect``, ``transfer``, ``compound``, ``remainder``, ``allan``, ...).
        """
        transfer = self.transfer or {'fitness_gap_before': None, 'fitness_gap_after': None,
                                     'trials': 0}
        return {'format': FORMAT, 'where': self.where, 'effects': self.effects,
                'top_effect': self.top_effect, 'transfer': transfer,
                'gap_significant': self.gap_significant, 'combined': self.combined,
                'localisation': self.localisation,
                'compound': None if self.compound is None else self.compound.to_json(),
                'remainder': self.remainder,
                'allan': self.allan, 'rounding': self.rounding,
                'notes': self.notes, 'inputs': self.inputs}


def check(recordings: list[Recording]) -> None:
    """Refuse input the diagnosis cannot make sense of, saying what is wrong.

    Args:
        recordings: the real recordings to be diagnosed together (one robot).

    Raises:
        ValueError: a one-line message naming the recording and what is wrong (none
            given, too few samples, different channel layouts, no variation, a
            closed-loop recording without its genome).
    """
    if not recordings:
        raise ValueError('the diagnosis needs at least one recording')
    for i, rec in enumerate(recordings):
        rec.check()
        if len(rec) < MIN_SAMPLES:
            raise ValueError(f'recording {_name(rec, i)} has {len(rec)} samples; the '
                             f'diagnosis needs at least {MIN_SAMPLES}')
    layouts = {(r.channels, tuple(r.channels_used)) for r in recordings}
    if len(layouts) > 1:
        described = '; '.join(f'{_name(r, i)}: {r.channels} channels, using '
                              f'{r.channels_used}' for i, r in enumerate(recordings))
        raise ValueError(f'the recordings disagree on their light channels ({described}); '
                         f'diagnose recordings of one robot together')
    for i, rec in enumerate(recordings):
        if replay.kind(rec) == 'stationary' and not _varies(rec):
            raise ValueError(f'recording {_name(rec, i)} has no variation: every used channel '
                             f'is constant at every heading, so its noise cannot be compared '
                             f'(a disconnected or stuck sensor?)')
        if replay.kind(rec) == 'closed_loop':
            replay.genome_of(rec)


def _varies(rec: Recording) -> bool:
    used = rec.readings[:, rec.channels_used]
    for run in replay.runs(rec):
        if np.ptp(used[run], axis=0).max() > 0:
            return True
    return False


def _name(rec: Recording, i: int) -> str:
    return str(rec.manifest.get('name', f'#{i + 1}'))


def diagnose(recordings: list[Recording], options: Options = Options(), reality=None,
             transfer_trials: int = 0, transfer_ea=None) -> Diagnosis:
    """Diagnose the gap between ``recordings`` and the simulator of ``options.config``.

    Args:
        recordings: real recordings of one robot (stationary, closed-loop or both).
        options: the simulator's configuration, seed, hold-out, thresholds, candidates.
        reality: ``(genomes, seeds) -> fitness`` on the real robot, for the transfer
            experiment; None to skip it.
        transfer_trials: trials per arm of the transfer experiment (0: not run).
        transfer_ea: the evolutionary algorithm's settings for it.

    Returns:
        The ``Diagnosis``: where the gap lies, every candidate effect alone (ranked),
        the top effect, the compound set chosen by forward selection, the remainder
        with its empirical model, the Allan profiles and notes.  ``to_json()`` gives
        diagnosis.json.

    Raises:
        ValueError: bad recordings or options (see ``check``), with a one-line message.
    """
    check(recordings)
    o = options
    notes = _base_notes(recordings, o.base)
    full = Target(recordings, o.config, o.seed, o.base, replicates=o.replicates)
    c_full = full.compare()
    significant = bool(c_full.significant(o.alpha).any())
    result = Diagnosis(entries(c_full, o.where_limit, o.alpha), localise(c_full, o.alpha), [],
                       'none', None, significant, notes, c_full,
                       inputs=[_describe(r) for r in recordings])
    result.allan = _allan(full)
    if not significant:
        notes.append(f'the gap is not significant: no statistic of {len(c_full.keys)} differs '
                     f'from the simulator at family-wise alpha {o.alpha} (Holm)')
    if o.held_out:
        split.check_conditions(recordings, o.held_out)
    fit_part, test_part = split.split(recordings, o.held_out)
    if not fit_part or not test_part:
        notes.append('cannot tell which effect: the data cannot be split into a part to fit '
                     'and a part held out')
        return result
    a, b = (Target([r for _, r in part], o.config, o.seed + k, o.base,
                   replicates=o.replicates, block_lengths=[full.block_lengths[i]
                                                           for i, _ in part])
            for k, part in ((1, fit_part), (2, test_part)))
    candidates = fit.fit_all(a, a.compare(), o.effects)
    result.held_out_before = b.compare()
    d_before = result.held_out_before.discrepancy
    before_reps = b.replicate_discrepancies(result.held_out_before)
    scored = [_score(b, cand, d_before, before_reps, o) for cand in candidates]
    scored.sort(key=lambda s: -s[0]['heldout_reduction'])
    scored = _parsimonious(scored, o.alpha)
    if significant and o.rounding:
        a, b, scored, _ = _rounding(result, a, b, candidates, scored, d_before, before_reps,
                                    o)
    result.effects = [s[0] for s in scored]
    best, best_cmp, best_effect, _ = scored[0] if scored else (None, None, None, None)
    if significant and best is not None:
        if best_effect is not None and best['heldout_reduction'] >= o.min_reduction and \
                best['p_value'] < o.reduction_alpha:
            result.top_effect, result.fitted = best['name'], best_effect
            result.held_out_after = best_cmp
            if o.compound:
                result.compound = compound.select(
                    a, b, (best_effect, best['note'], best_cmp, scored[0][3]), o.effects,
                    d_before, before_reps, result.held_out_before)
                if o.rounding and len(result.compound.effects) > 1 and \
                        result.rounding['rounding'] == result.rounding['given']:
                    a, b = _late_rounding(result, a, b, d_before, o)
                result.held_out_after = result.compound.comparison
                result.combined = {'effects': [e.name for e in result.compound.effects],
                                   'discrepancy_before': d_before,
                                   'discrepancy_after': result.compound.discrepancy_after,
                                   'heldout_reduction': result.compound.reduction}
            else:
                result.combined = _combined(b, scored, d_before, o)
        else:
            notes.append(f'no effect explains a significant part of the gap: the best, '
                         f'{best["name"]}, removes {best["heldout_reduction"]:.0%} of the '
                         f'held-out discrepancy, p = {best["p_value"]:.3f} (needs '
                         f'{o.min_reduction:.0%}, p < {o.reduction_alpha})')
    if significant and o.remainder:
        _remainder(result, a, b, d_before, o)
    if result.fitted is not None and reality is not None and transfer_trials:
        result.transfer = _transfer(recordings, o, result.fitted, reality, transfer_trials,
                                    transfer_ea)
    return result


def _rounding(result: Diagnosis, a: Target, b: Target, candidates, scored, d_before: float,
              before_reps, o: Options, given=None, known=None) -> tuple:
    """(a, b, scored, the held-out comparison with ``given`` under the rounding chosen,
    None if it is kept) with the rounding the fitting part's value lattice prefers
    given the best effect (or ``given``, whose held-out comparison is ``known``;
    ``gap.rounding``), confirmed on the held-out part's lattice; with the other rounding
    every candidate is scored again (not when ``given`` is the compound:
    ``_late_rounding``)."""
    late = given is not None
    if not late:
        best = scored[0][2] if scored and scored[0][1] is not None else None
        given = [best] if best is not None else []
        known = scored[0][1] if best is not None else None
    choice = rounding.choose(a, given, o.reduction_alpha)
    if choice['rounding'] != a.config.noise.rounding:
        b2 = rounding.retarget(b, choice['rounding'])
        switched = b2.compare(given)
        known = known if known is not None else b.compare(given)
        held = {choice['given']: rounding.lattice(b, known)[0],
                choice['rounding']: rounding.lattice(b2, switched)[0]}
        choice['lattice_held_out'] = held
        if held[choice['rounding']] >= held[choice['given']]:
            choice['note'] += '; not confirmed on the held-out part: the given is kept'
            choice['rounding'] = choice['given']
    choice['given_effects'] = [e.name for e in given]
    result.rounding = choice
    if choice['rounding'] == a.config.noise.rounding:
        return a, b, scored, None
    a, b = rounding.retarget(a, choice['rounding']), b2
    if not late:
        result.notes.append(choice['note'])
        scored = [_score(b, cand, d_before, before_reps, o) for cand in candidates]
        scored.sort(key=lambda s: -s[0]['heldout_reduction'])
        scored = _parsimonious(scored, o.alpha)
    return a, b, scored, switched


def _late_rounding(result: Diagnosis, a: Target, b: Target, d_before: float,
                   o: Options) -> tuple:
    """The rounding asked again given the whole compound (a best effect that is a stand-in
    leaves the spreads too far off for the lattice to tell).  On a change the chosen
    effects are kept and scored again under it, and it is kept only if their held-out
    discrepancy falls (choosing the compound again would double the diagnosis's time)."""
    early = {k: result.rounding[k] for k in ('rounding', 'lattice', 'p_value')}
    effects = list(result.compound.effects)
    c = result.compound
    a2, b2, _, after = _rounding(result, a, b, [], [], d_before, None, o, effects,
                                 c.comparison)
    result.rounding['early'] = early
    if a2 is a:
        return a, b
    if after.discrepancy >= c.discrepancy_after:
        result.rounding['rounding'] = result.rounding['given']
        result.rounding['note'] += (f'; the chosen effects\' held-out discrepancy does not '
                                    f'fall ({c.discrepancy_after:.1f} to '
                                    f'{after.discrepancy:.1f}): the given is kept')
        return a, b
    result.rounding['note'] += (f'; the chosen effects\' held-out discrepancy '
                                f'{c.discrepancy_after:.1f} -> {after.discrepancy:.1f}')
    result.notes.append(result.rounding['note'])
    c.comparison, c.discrepancy_after = after, after.discrepancy
    c.replicates = b2.replicate_discrepancies(after)
    return a2, b2


def _remainder(result: Diagnosis, a: Target, b: Target, d_before: float, o: Options) -> None:
    """What the named effects leave on held-out data, and the empirical model of it."""
    named = result.fitted_effects
    after = result.held_out_after if named else result.held_out_before
    out = remainder.describe(after, d_before, o.alpha)
    out['named_effects'] = [e.name for e in named]
    out['heldout_reduction_named'] = 1.0 - after.discrepancy / d_before if d_before > 0 \
        else 0.0
    try:
        empirical = remainder.fit(a.with_given(named))
        with_empirical = b.compare(named + [empirical]) if empirical is not None else None
    except Exception as exc:      # noqa: BLE001 - the fallback failing leaves the rest
        empirical, with_empirical = None, None
        out['note'] = f'the empirical model could not be fitted: {type(exc).__name__}: {exc}'
    if empirical is not None:
        out['empirical'] = fx.to_dict(empirical)
        out['heldout_reduction_with_empirical'] = 1.0 - with_empirical.discrepancy / d_before \
            if d_before > 0 else 0.0
        if with_empirical.discrepancy < after.discrepancy:
            result.empirical = empirical
    result.remainder = out


def _allan(full: Target) -> dict | None:
    """Allan deviation profiles of the stationary recordings, real and simulated."""
    real = [r for r, k in zip(full.recordings, full.kinds) if k == 'stationary']
    if not real:
        return None
    sim = full.simulate(kinds=('stationary',), copies=1)
    factors = allan.taus(max(r.size for r in replay.runs(real[0])))
    return allan.compare(allan.profile(real[0], factors), allan.profile(sim[0], factors))


def _parsimonious(scored: list, alpha: float) -> list:
    """Move the simplest effect first among those that explain the held-out data as well as
    the best: a held-out discrepancy left within ``TIE`` (relative) of the best's, or
    not beaten significantly (the best's discrepancy lower in 1 - alpha of the bootstrap
    replicates, paired: the same resampled real data against both)."""
    if len(scored) < 2 or scored[0][3] is None:
        return scored
    best = scored[0]
    left = best[0]['discrepancy_after']
    rivals = [s for s in scored[1:] if s[3] is not None
              and PARAMETERS[s[0]['name']] < PARAMETERS[best[0]['name']]
              and (s[0]['discrepancy_after'] <= (1 + TIE) * left
                   or np.mean(best[3] < s[3]) < 1 - alpha)]
    if not rivals:
        return scored
    simplest = min(rivals, key=lambda s: (PARAMETERS[s[0]['name']],
                                          -s[0]['heldout_reduction']))
    simplest[0]['note'] += (f'; ranked first: explains the held-out data as well as '
                            f'{best[0]["name"]} with fewer parameters')
    return [simplest] + [s for s in scored if s is not simplest]


def _score(b: Target, cand: fit.Candidate, d_before: float, before_reps, o: Options):
    """(effects entry, held-out comparison, effect, replicate discrepancies after)."""
    entry = {'name': cand.name, 'sensors': [], 'parameters': {},
             'discrepancy_before': d_before, 'discrepancy_after': d_before,
             'heldout_reduction': 0.0, 'reduction_interval': [0.0, 0.0], 'p_value': 1.0,
             'note': cand.note}
    if cand.effect is None or d_before <= 0:
        return entry, None, cand.effect, None
    try:
        after = b.compare([cand.effect])
    except Exception as exc:      # noqa: BLE001 - the candidate cannot run: not fitting
        entry['note'] = f'{cand.note}; cannot be scored: {type(exc).__name__}: {exc}'
        return entry, None, None, None
    after_reps = b.replicate_discrepancies(after)
    reduction = 1.0 - after.discrepancy / d_before
    # Resampling adds noise to both discrepancies, which biases the replicates' reduction
    # down; shifting them to the estimate's median gives a bias-corrected interval.
    reps = 1.0 - after_reps / np.maximum(before_reps, 1e-9)
    reps += reduction - np.median(reps)
    entry.update({
        'sensors': list(cand.effect.sensors), 'parameters': _parameters(cand.effect),
        'discrepancy_after': after.discrepancy, 'heldout_reduction': reduction,
        'reduction_interval': [float(np.quantile(reps, 0.025)),
                               float(np.quantile(reps, 0.975))],
        'p_value': float((np.sum(reps <= 0) + 1) / (reps.size + 1))})
    return entry, after, cand.effect, after_reps


def _combined(b: Target, scored: list, d_before: float, o: Options) -> dict | None:
    """The top two effects added together, when the second also removes a share alone."""
    if len(scored) < 2 or scored[1][2] is None or \
            scored[1][0]['heldout_reduction'] < o.min_reduction:
        return None
    pair = [scored[0][2], scored[1][2]]
    after = b.compare(pair).discrepancy
    return {'effects': [e.name for e in pair], 'discrepancy_before': d_before,
            'discrepancy_after': after, 'heldout_reduction': 1.0 - after / d_before}


def _parameters(effect) -> dict:
    params = fx.parameters(effect)
    if effect.name == fx.CorrelatedNoise.name:
        params['groups'] = effect.location
    return params


def _base_notes(recordings, requested: str) -> list[str]:
    notes = []
    for i, rec in enumerate(recordings):
        if replay.kind(rec) == 'stationary':
            mode, why = replay.base_mode(rec, requested)
            if mode == 'observed':
                notes.append(f'recording {_name(rec, i)}: simulated base values are the '
                             f'recording\'s own means ({why}); levels and sensor_gain_offset '
                             f'are not assessed')
    kinds = {replay.kind(r) for r in recordings}
    if 'closed_loop' not in kinds:
        notes.append('no closed-loop recording: actuator_turn_error (and latency in turns) '
                     'cannot be assessed')
    return notes


def _describe(rec: Recording) -> dict:
    return {'protocol': replay.kind(rec), 'samples': len(rec),
            'episodes': int(np.unique(rec.episode).size), 'conditions': rec.conditions(),
            'channels': rec.channels, 'channels_used': rec.channels_used,
            'source': rec.manifest.get('source')}


def _transfer(recordings, o: Options, effect, reality, trials: int, ea) -> dict | None:
    loops = [r for r in recordings if replay.kind(r) == 'closed_loop']
    if not loops:
        return None
    label = loops[0].conditions()[0]
    world = replay.condition_world(loops[0], label, o.config.world)
    kw = {} if ea is None else {'ea': ea}
    out = transfer.run(o.config, world, [effect], reality, trials, seed=o.seed, **kw)
    out['condition'] = label
    return out
