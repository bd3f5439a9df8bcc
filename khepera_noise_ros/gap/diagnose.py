"""The diagnosis: where the gap lies, which unmodelled effect causes it, how far adding it
shrinks the gap on held-out data (the steps: docs/diagnosis.md, "How it works")."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from ..core.noise import ROUNDINGS
from ..effects import DEFAULT, WORLD_MODEL, Effect, EmpiricalNoise
from ..effects.base import Array, Candidate, Key
from ..effects.fitting import ALPHA
from ..recording import Recording
from . import allan, bootstrap, split
from .compare import Comparison, entries, localise, paired_p, reduction
from .families import having
from .protocol import base_mode, check, kind, name, runs
from .select import (MIN_ADDED, MIN_REDUCTION, STEP_ALPHA, Compound, Selection, as_good,
                     fit_given, fit_one, loop_worse, simpler)
from ..simconfig import SimConfig
from .target import Target

FORMAT = 'khepera-noise-diagnosis/1'
REDUCTION_ALPHA = 0.05     # ... and do so in 95% of the bootstrap replicates
LATTICE_SHARE = 0.25       # of the lattice statistics' discrepancy another rounding removes
LATTICE_REPLICATES = 60


@dataclass
class Options:
    config: SimConfig = field(default_factory=SimConfig)
    seed: int = 0
    base: str = 'auto'
    held_out: tuple[str, ...] = ()   # conditions held out of the fit; () = alternate episodes
    alpha: float = ALPHA                        # family-wise, for "is there a gap"
    reduction_alpha: float = REDUCTION_ALPHA    # one-sided, for "does the effect shrink it"
    min_reduction: float = MIN_REDUCTION
    replicates: int = bootstrap.REPLICATES
    effects: tuple[str, ...] = DEFAULT
    where_limit: int = 40
    compound: bool = True         # forward selection of a set of effects after the best one
    remainder: bool = True        # describe what is left and fit the empirical model
    rounding: bool = True         # choose where the simulator rounds from the value lattice


@dataclass
class World:
    """The world model's parts identified before the effects (docs/identification.md)."""
    effects: list[Effect]
    before: float                     # held-out discrepancy of the stock simulator
    after: float                      # ... with the world identified
    p_value: float
    notes: dict[str, str] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {**_summary(self.effects, self.before, self.after), 'p_value': self.p_value,
                'notes': self.notes, 'effects': [{'name': e.name, 'sensors': list(e.sensors),
                                                  'parameters': e.parameters()}
                                                 for e in self.effects]}


@dataclass
class Diagnosis:
    where: list[dict[str, Any]]
    localisation: dict[str, Any]
    effects: list[dict[str, Any]]
    top_effect: str
    fitted: Effect | None            # the top effect, ready for the simulator
    gap_significant: bool
    notes: list[str]
    full: Comparison                 # real against simulated, all data
    held_out_before: Comparison | None = None
    held_out_after: Comparison | None = None
    transfer: dict[str, Any] | None = None
    inputs: list[dict[str, Any]] = field(default_factory=list)
    combined: dict[str, Any] | None = None
    compound: Compound | None = None
    remainder: dict[str, Any] | None = None
    empirical: Effect | None = None  # the empirical model, when it brings the simulator closer
    allan: dict[str, Any] | None = None
    rounding: dict[str, Any] | None = None
    world: World | None = None   # the world model's parts, in the simulator

    @property
    def fitted_effects(self) -> list[Effect]:
        """What fitted_params.yaml loads: the world identified, then the named effects."""
        return ([] if self.world is None else list(self.world.effects)) + self.named_effects

    @property
    def named_effects(self) -> list[Effect]:
        """The effects chosen beside the world: the compound set, else the top effect."""
        if self.compound is not None:
            return list(self.compound.effects)
        return [] if self.fitted is None else [self.fitted]

    def simulator(self, config: SimConfig) -> SimConfig:
        """``config`` with the rounding the diagnosis chose (what fitted_params.yaml has)."""
        return with_rounding(config, self.rounding['rounding']) if self.rounding else config

    def to_json(self) -> dict[str, Any]:
        """diagnosis.json: the keys of format 1 plus this project's additions."""
        transfer = self.transfer or {'fitness_gap_before': None, 'fitness_gap_after': None,
                                     'trials': 0}
        return {'format': FORMAT, 'where': self.where, 'effects': self.effects,
                'top_effect': self.top_effect, 'transfer': transfer,
                'gap_significant': self.gap_significant, 'combined': self.combined,
                'localisation': self.localisation,
                'compound': None if self.compound is None else self.compound.to_json(),
                'remainder': self.remainder, 'allan': self.allan, 'rounding': self.rounding,
                'world': None if self.world is None else self.world.to_json(),
                'notes': self.notes, 'inputs': self.inputs}


Scored = tuple[dict[str, Any], Comparison | None, Effect | None, Array | None]


def diagnose(recordings: Sequence[Recording], options: Options = Options()) -> Diagnosis:
    """The gap between ``recordings`` (one robot: stationary, closed-loop or both) and the
    simulator of ``options.config``; ValueError (one line) on bad recordings or options."""
    check(recordings)
    o = options
    unknown = [n for n in o.effects if n not in DEFAULT]
    if unknown:
        raise ValueError(f'unknown effect(s) {unknown}; the vocabulary is {list(DEFAULT)}')
    notes = _base_notes(recordings, o.base)
    full = Target(recordings, o.config, o.seed, o.base, replicates=o.replicates)
    c_full = full.compare()
    significant = bool(c_full.significant(o.alpha).any())
    result = Diagnosis(entries(c_full, o.where_limit, o.alpha), localise(c_full, o.alpha), [],
                       'none', None, significant, notes, c_full,
                       inputs=[_describe(r) for r in recordings], allan=_allan(full))
    if not significant:
        notes.append(f'the gap is not significant: no statistic of {len(c_full.keys)} differs '
                     f'from the simulator at family-wise alpha {o.alpha} (Holm)')
    if noisier := _noisier(c_full, o.alpha):
        notes.append(noisier)
    if o.held_out:
        split.check_conditions(recordings, o.held_out)
    fit_part, test_part = split.split(list(recordings), o.held_out)
    if not fit_part or not test_part:
        notes.append('cannot tell which effect: the data cannot be split into a part to fit '
                     'and a part held out')
        return result
    a, b = (Target([r for _, r in part], o.config, o.seed + k, o.base, replicates=o.replicates,
                   block_lengths=[full.block_lengths[i] for i, _ in part],
                   cache=full.memory.cache)
            for k, part in ((1, fit_part), (2, test_part)))
    parts: dict[str, str] = {}
    world = _world(a, b, b.compare(), o, parts) if significant else None
    if world is None and parts:     # never silent about a part its protocol would identify
        notes.append('the world model is the simulator\'s own: ' + '; '.join(
            f'{name}: {note}' for name, note in parts.items()))
    if world is not None:         # the simulator identified: its world, then the effects
        result.world = world
        notes.append(f'the world identified: {", ".join(e.name for e in world.effects)} '
                     f'remove {reduction(world.before, world.after):.0%} of the held-out '
                     'discrepancy')
        a, b = (t.with_config(t.config.with_effects(*world.effects)) for t in (a, b))
    c_a = a.compare()
    candidates = [fit_one(n, a, c_a) for n in o.effects if n not in WORLD_MODEL]
    result.held_out_before = before = b.compare()
    d_before = before.discrepancy
    before_reps = b.replicate_discrepancies(before)

    def rank(b: Target, base: Comparison) -> list[Scored]:
        scored = sorted((_score(b, cand, d_before, before_reps, base) for cand in candidates),
                        key=lambda s: (bool(s[0].get('closed_loop_worse')),
                                       -s[0]['heldout_reduction']))
        return _parsimonious(scored, o.alpha)
    scored = rank(b, before)
    if significant and o.rounding:
        best = scored[0][2] if scored and scored[0][1] is not None else None
        known = scored[0][1] if best is not None else None
        a2, b2, _ = _rounding(result, a, b, [best] if best else [], known, o)
        if b2 is not b:
            a, b = a2, b2
            notes.append(result.rounding['note'] if result.rounding else '')
            scored = rank(b, b.compare())
    result.effects = [s[0] for s in scored]
    best_entry, best_cmp, best_effect, best_reps = scored[0] if scored else (None,) * 4
    # beside an identified world the effects refine it: the first needs the compound's share
    least = o.min_reduction if world is None else MIN_ADDED
    if significant and best_entry is not None:
        if best_effect is not None and best_cmp is not None and best_reps is not None and \
                best_entry['heldout_reduction'] >= least and \
                best_entry['p_value'] < o.reduction_alpha and \
                not best_entry.get('closed_loop_worse'):
            result.top_effect, result.fitted = best_entry['name'], best_effect
            result.held_out_after = best_cmp
            if o.compound:
                a, b = _compound(result, a, b, (best_effect, best_entry['note'], best_cmp,
                                                best_reps), before_reps, o)
            else:
                result.combined = _combined(b, scored, d_before, o)
        else:
            notes.append(f'no effect explains a significant part of the gap: the best, '
                         f'{best_entry["name"]}, removes {best_entry["heldout_reduction"]:.0%} '
                         f'of the held-out discrepancy, p = {best_entry["p_value"]:.3f} (needs '
                         f'{least:.0%}, p < {o.reduction_alpha})')
    if significant and o.remainder:
        _remainder(result, a, b, d_before, o)
    return result


def _noisier(c: Comparison, alpha: float) -> str:
    """A note when most significant spread statistics are larger simulated than real, by
    half or more at the median, per unit of the cell's level where it has one (the model's
    noise grows with the reading; a cell at the brightest reading says nothing): every
    effect adds variation, so none can close that part of the gap."""
    ratios = []
    for i in np.flatnonzero(c.significant(alpha)):
        k = c.keys[i]
        j = c.index.get(Key('level', k.sensors, k.condition, k.part))
        if k.family == 'spread' and (j is None or c.real[j] > 0 < c.sim[j]):
            level = 1.0 if j is None else c.real[j] / c.sim[j]
            ratios.append(c.sim[i] * level / max(c.real[i], 1e-9))
    above = int(np.sum(np.array(ratios) > 1.0))
    if len(ratios) < 3 or above < 0.75 * len(ratios) or np.median(ratios) < 1.5:
        return ''
    return (f'the simulator is noisier than the robot: its spread is larger in {above} of '
            f'{len(ratios)} significant spread statistics (median {np.median(ratios):.1f} '
            'times, per unit of level); the effects only add variation, so lower the noise '
            'levels of --params and diagnose again')


def _world(a: Target, b: Target, before: Comparison, o: Options,
           notes: dict[str, str]) -> World | None:
    """The world model's parts among ``o.effects`` fitted on ``a`` in order, each given those
    before it (the light shapes what a sensor follows, and both what a turn shows), then
    dropped while that lowers the held-out discrepancy on ``b``, and left to its plain case
    (``Effect.plain``: nested in it) where that fitted in its place lowers it more; kept if
    the set lowers it significantly from ``before``. ``notes`` gets each part's note."""
    fitted: list[Effect] = []
    for part in (n for n in WORLD_MODEL if n in o.effects):
        cand = fit_given(part, a, fitted)
        notes[part] = cand.note
        if cand.effect is not None:
            fitted.append(cand.effect)
    if not fitted:
        return None
    current = b.compare(fitted)
    while fitted:                 # drop the part whose absence the held-out data prefer
        trials = [(b.compare(fitted[:i] + fitted[i + 1:]), i) for i in range(len(fitted))]
        best, i = min(trials, key=lambda t: t[0].discrepancy)
        if best.discrepancy >= current.discrepancy:
            break
        notes[fitted[i].name] += '; dropped: the held-out data are closer without it'
        fitted.pop(i)
        current = best
    for effect in [e for e in fitted if e.plain in o.effects]:
        others = [e for e in fitted if e is not effect]
        plain = fit_given(str(effect.plain), a, others).effect
        if plain is None:
            continue
        rival = b.compare(others + [plain])
        if rival.discrepancy < current.discrepancy:
            notes[effect.name] += (f'; left to {effect.plain}: the held-out data are closer '
                                   f'with it ({current.discrepancy:.1f} -> '
                                   f'{rival.discrepancy:.1f})')
            fitted, current = others, b.compare(others)
    if not fitted:
        return None
    p = paired_p(b.replicate_discrepancies(before), b.replicate_discrepancies(current),
                 before.discrepancy, current.discrepancy)
    if p >= STEP_ALPHA or current.discrepancy >= before.discrepancy:
        return None
    return World(fitted, before.discrepancy, current.discrepancy, p, notes)


def _compound(result: Diagnosis, a: Target, b: Target,
              best: tuple[Effect, str, Comparison, Array], before_reps: Array,
              o: Options) -> tuple[Target, Target]:
    """The compound set chosen from the best single effect (and the rounding asked again)."""
    before = result.held_out_before
    assert before is not None
    c = result.compound = Selection(a, b, before, before.discrepancy).run(
        best, [n for n in o.effects if n not in WORLD_MODEL], before_reps)
    if o.rounding and len(c.effects) > 1 and result.rounding and \
            result.rounding['rounding'] == result.rounding['given']:
        a, b = _late_rounding(result, a, b, o)
    result.held_out_after = c.comparison
    result.combined = _summary(c.effects, before.discrepancy, c.discrepancy_after)
    return a, b


def _summary(effects: Sequence[Effect], before: float, after: float) -> dict[str, Any]:
    return {'effects': [e.name for e in effects], 'discrepancy_before': before,
            'discrepancy_after': after, 'heldout_reduction': reduction(before, after)}


def _score(b: Target, cand: Candidate, d_before: float, before_reps: Array,
           base: Comparison) -> Scored:
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
    share = reduction(d_before, after.discrepancy)
    # resampling biases the replicates' reduction down: shifted to the estimate's median
    reps = 1.0 - after_reps / np.maximum(before_reps, 1e-9)
    reps += share - np.median(reps)
    entry.update({'sensors': list(cand.effect.sensors), 'parameters': cand.effect.parameters(),
                  'discrepancy_after': after.discrepancy, 'heldout_reduction': share,
                  'reduction_interval': [float(np.quantile(reps, 0.025)),
                                         float(np.quantile(reps, 0.975))],
                  'p_value': float((np.sum(reps <= 0) + 1) / (reps.size + 1))})
    if worse := loop_worse(b, [], [cand.effect], base, after):
        entry['closed_loop_worse'] = worse
        entry['note'] = f'{cand.note}; predicts the held-out closed loop ({worse}) worse: not kept'
    return entry, after, cand.effect, after_reps


def _parsimonious(scored: list[Scored], alpha: float) -> list[Scored]:
    """The simplest effect first among those that explain the held-out data as well as
    the best (``select.as_good``)."""
    if len(scored) < 2 or scored[0][3] is None:
        return scored
    best, best_reps = scored[0], scored[0][3]
    simplest = next((s for s in simpler(scored[1:], best[0]['name'], lambda s: s[0]['name'],
                                        lambda s: -s[0]['heldout_reduction'])
                     if s[3] is not None and s[0]['heldout_reduction'] > 0
                     and not s[0].get('closed_loop_worse')
                     and as_good(best[0]['discrepancy_after'], best_reps,
                                 s[0]['discrepancy_after'], s[3], alpha)), None)
    if simplest is None:
        return scored
    simplest[0]['note'] += (f'; ranked first: explains the held-out data as well as '
                            f'{best[0]["name"]} with fewer parameters')
    return [simplest] + [s for s in scored if s is not simplest]


def _combined(b: Target, scored: list[Scored], d_before: float,
              o: Options) -> dict[str, Any] | None:
    """The top two effects added together, when the second also removes a share alone."""
    if len(scored) < 2 or scored[1][2] is None or \
            scored[1][0]['heldout_reduction'] < o.min_reduction or scored[0][2] is None:
        return None
    pair = [scored[0][2], scored[1][2]]
    return _summary(pair, d_before, b.compare(pair).discrepancy)


# -- where the simulator rounds ---------------------------------------------------------

def with_rounding(config: SimConfig, rounding: str) -> SimConfig:
    return dataclasses.replace(config, noise=dataclasses.replace(config.noise, rounding=rounding))


def _lattice(t: Target, c: Comparison) -> tuple[float, Array]:
    """(the lattice statistics' part of ``c``'s discrepancy, the same per real replicate)."""
    part = c.select([k.family in having('lattice') for k in c.keys])
    if not part.keys:
        return 0.0, np.zeros(max(t.real.values.shape[0] - 1, 1))
    return part.discrepancy, t.replicate_discrepancies(part)


def _rounding(result: Diagnosis, a: Target, b: Target, given: list[Effect],
              known: Comparison | None, o: Options) -> tuple[Target, Target, Comparison | None]:
    """(a, b, the held-out comparison with ``given`` if switched) under the rounding the
    value lattice prefers with ``given`` in the simulator: the other only if it lowers the
    lattice statistics' discrepancy by ``LATTICE_SHARE`` (paired p < ``reduction_alpha``)
    on the fitting part and lowers it on the held-out part too."""
    here = a.config.noise.rounding
    other = next(r for r in ROUNDINGS if r != here)
    d0, reps0 = _lattice(a, a.compare(given, replicates=LATTICE_REPLICATES))
    alt = a.with_config(with_rounding(a.config, other))
    d1, reps1 = _lattice(alt, alt.compare(given, replicates=LATTICE_REPLICATES))
    p = paired_p(reps0, reps1, d0, d1)
    better = d0 > 0 and d1 <= (1.0 - LATTICE_SHARE) * d0 and p < o.reduction_alpha
    choice: dict[str, Any] = {'rounding': other if better else here, 'given': here,
                              'lattice': {here: d0, other: d1}, 'p_value': p}
    if d0 <= 0 and d1 <= 0:
        choice['note'] = 'no value-lattice statistic differs: the given rounding is kept'
    else:
        choice['note'] = (f"value-lattice statistics' discrepancy {d0:.1f} rounding at the "
                          f'{here}, {d1:.1f} at the {other} (p = {p:.3f}): ' +
                          (f'the simulator rounds at the {other}' if better
                           else f'the {here} is kept'))
    if better:
        b2 = b.with_config(with_rounding(b.config, other))
        switched = b2.compare(given)
        held = {here: _lattice(b, known if known is not None else b.compare(given))[0],
                other: _lattice(b2, switched)[0]}
        choice['lattice_held_out'] = held
        if held[other] >= held[here]:
            choice['note'] += '; not confirmed on the held-out part: the given is kept'
            choice['rounding'] = here
    choice['given_effects'] = [e.name for e in given]
    result.rounding = choice
    if choice['rounding'] == here:
        return a, b, None
    return alt, b2, switched


def _late_rounding(result: Diagnosis, a: Target, b: Target, o: Options) -> tuple[Target, Target]:
    """The rounding asked again given the whole compound (a stand-in chosen first can leave
    the spreads too far off for the lattice to tell), kept if the compound does better."""
    assert result.compound is not None and result.rounding is not None
    early = {k: result.rounding[k] for k in ('rounding', 'lattice', 'p_value')}
    c = result.compound
    a2, b2, after = _rounding(result, a, b, list(c.effects), c.comparison, o)
    result.rounding['early'] = early
    if after is None:
        return a, b
    if after.discrepancy >= c.discrepancy_after:
        result.rounding['rounding'] = result.rounding['given']
        result.rounding['note'] += (f"; the chosen effects' held-out discrepancy does not "
                                    f'fall ({c.discrepancy_after:.1f} to '
                                    f'{after.discrepancy:.1f}): the given is kept')
        return a, b
    result.rounding['note'] += (f"; the chosen effects' held-out discrepancy "
                                f'{c.discrepancy_after:.1f} -> {after.discrepancy:.1f}')
    result.notes.append(result.rounding['note'])
    c.comparison, c.discrepancy_after = after, after.discrepancy
    return a2, b2


# -- what is left ----------------------------------------------------------------------

def _remainder(result: Diagnosis, a: Target, b: Target, d_before: float, o: Options) -> None:
    """What the named effects leave on held-out data, and the empirical model of it."""
    named = result.named_effects
    after = result.held_out_after if named and result.held_out_after is not None \
        else result.held_out_before
    assert after is not None
    sig = after.significant(o.alpha)
    out: dict[str, Any] = {
        'significant': bool(sig.any()), 'statistics_off': int(sig.sum()),
        'discrepancy': after.discrepancy,
        'share_of_gap_left': after.discrepancy / d_before if d_before > 0 else 0.0,
        'where': [e for e in entries(after, 10, o.alpha) if e['significant']],
        'localisation': localise(after, o.alpha), 'named_effects': [e.name for e in named],
        'heldout_reduction_named': reduction(d_before, after.discrepancy)}
    try:
        empirical = EmpiricalNoise.fit(a.with_given(named).evidence(None)).effect
        with_empirical = b.compare(named + [empirical]) if empirical is not None else None
    except Exception as exc:      # noqa: BLE001 - the fallback failing leaves the rest
        empirical, with_empirical = None, None
        out['note'] = f'the empirical model could not be fitted: {type(exc).__name__}: {exc}'
    if empirical is not None and with_empirical is not None:
        out['empirical'] = empirical.to_dict()
        out['heldout_reduction_with_empirical'] = reduction(d_before, with_empirical.discrepancy)
        if with_empirical.discrepancy < after.discrepancy:
            result.empirical = empirical
    result.remainder = out


def _allan(full: Target) -> dict[str, Any] | None:
    """Allan deviation profiles of the stationary recordings, real and simulated."""
    real = full.of_kind('stationary')
    if not real:
        return None
    sim = full.simulate(kinds=('stationary',), copies=1)
    factors = allan.taus(max(r.size for r in runs(real[0])))
    return allan.compare(allan.profile(real[0], factors), allan.profile(sim[0].recording, factors))


def _base_notes(recordings: Sequence[Recording], requested: str) -> list[str]:
    notes = []
    for i, rec in enumerate(recordings):
        if kind(rec) == 'stationary':
            mode, why = base_mode(rec, requested)
            if mode == 'observed':
                notes.append(f"recording {name(rec, i)}: simulated base values are the "
                             f"recording's own means ({why}); levels and sensor_gain_offset "
                             f'are not assessed')
    if 'closed_loop' not in {kind(r) for r in recordings}:
        notes.append('no closed-loop recording: actuator_turn_error (and latency in turns) '
                     'cannot be assessed')
    return notes


def _describe(rec: Recording) -> dict[str, Any]:
    return {'protocol': kind(rec), 'samples': len(rec),
            'episodes': int(np.unique(rec.episode).size), 'conditions': rec.conditions(),
            'channels': rec.channels, 'channels_used': rec.channels_used,
            'source': rec.manifest.get('source')}
