"""Real recordings held against the simulator: the real statistics once, replays on demand,
their caches in one ``Memory``, and the ``Evidence`` a fitter sees."""
from __future__ import annotations

import copy
import functools
import dataclasses
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
from scipy import sparse

from ..effects import Effect
from ..effects.base import AnyArray, Array, Key, Row
from ..effects.simulate import SimCache
from ..memo import Recent, once
from ..recording import Recording
from . import bootstrap, closedloop, converter, dropouts, evidence, stationary, turns
from .compare import (MARGIN, Z_CAP, Comparison, Stats, compare, discrepancy, floors, recount,
                      replicate_discrepancies)
from .families import FAMILIES, having, of_part
from ..simconfig import SimConfig
from .protocol import condition_world, episodes, kind, runs
from .replay import Replayer

SIM_COPIES = 3
SIM_REPLICATES = 60      # bootstrap replicates of the simulated side in ``compare``
SIM_SAMPLES = 20_000     # simulated samples aimed at when choosing the number of copies
REPLAYS = 16             # replays remembered
NULL_DRAWS, NULL_SEED = 2, 104729     # simulated stand-ins for the real data (group_null)


@dataclass
class Repaired:
    """A recording with its dropouts repaired, their marks and each channel's extremes."""

    recording: Recording
    marks: Array
    ends: Array
    kind: str

    @staticmethod
    def of(rec: Recording, runs: dropouts.Runs | None = None) -> 'Repaired':
        k = kind(rec)
        readings, marks, ends = dropouts.repair(
            rec.readings, runs or dropouts.Runs(episodes(rec), len(rec)), k == 'closed_loop')
        if readings is not rec.readings:
            rec = dataclasses.replace(rec, readings=readings)
        return Repaired(rec, marks, ends, k)


@dataclass
class Memory:
    """What the simulations of one target and its copies share."""

    cache: SimCache = field(default_factory=SimCache)
    replayers: dict[tuple[int, SimConfig], Replayer] = field(default_factory=dict)
    replays: Recent[tuple[Any, ...], Repaired] = field(default_factory=lambda: Recent(REPLAYS))
    layouts: dict[tuple[int, int], stationary.Layout] = field(default_factory=dict)
    objectives: dict[tuple[Any, ...], float] = field(default_factory=dict)
    comparisons: dict[tuple[Any, ...], Comparison] = field(default_factory=dict)
    own: dict[tuple[Any, ...], tuple[Array, ...]] = field(default_factory=dict)
    plans: dict[tuple[int, int], tuple[Any, ...]] = field(default_factory=dict)
    nulls: dict[tuple[Any, ...], Array] = field(default_factory=dict)
    pairs: dict[tuple[Any, ...], tuple[AnyArray, AnyArray, Array]] = field(default_factory=dict)
    runs: dict[tuple[int, int], dropouts.Runs] = field(default_factory=dict)
    cuts: dict[tuple[int, int], list[np.ndarray]] = field(default_factory=dict)   # ``runs``
    real: dict[tuple[int, ...], Stats] = field(default_factory=dict)   # joined, by recording
    weights: Recent[tuple[Any, ...], Array] = field(default_factory=lambda: Recent(8))
    levels: dict[tuple[int, int], tuple[tuple[Key, ...], np.ndarray, np.ndarray]] = field(
        default_factory=dict)                     # the cell levels among a replay's keys


class Target:
    def __init__(self, recordings: Sequence[Recording], config: SimConfig, seed: int = 0,
                 base: str = 'auto', replicates: int = bootstrap.REPLICATES,
                 block_lengths: Sequence[int] = (), cache: SimCache | None = None):
        self.real_data = [Repaired.of(r) for r in recordings]
        self.recordings = [r.recording for r in self.real_data]
        self.config, self.seed, self.base, self.replicates = config, seed, base, replicates
        self.given: tuple[Effect, ...] = ()
        self.samples = sum(len(r) for r in self.recordings)
        # enough simulated samples, not more: fits cost less (a long recording: one copy)
        self.copies = int(np.clip(round(SIM_SAMPLES / max(self.samples, 1)), 1, SIM_COPIES))
        self.kinds = [r.kind for r in self.real_data]
        self.block_lengths = list(block_lengths) or [
            0 if r.kind == 'closed_loop' else stationary.block_length(
                r.recording, r.recording.channels_used) for r in self.real_data]
        self.loop_only = 'stationary' not in self.kinds      # the loop's value statistics
        self.memory = Memory(cache if cache is not None else SimCache())
        self._real = [self._stats(i, r, replicates, seed + i)
                      for i, r in enumerate(self.real_data)]
        self.real = Stats.join(self._real)
        self.channels = list(self.recordings[0].channels_used)
        self.counts = dropouts.counts(self.real_data)

    def with_given(self, effects: Sequence[Effect]) -> 'Target':
        """This target with ``effects`` always in the simulator: a candidate fitted against
        it is fitted jointly with them."""
        return self._copy(given=tuple(effects))

    def with_seed(self, seed: int) -> 'Target':
        return self._copy(seed=seed)

    def with_config(self, config: SimConfig) -> 'Target':
        return self._copy(config=config)

    def _copy(self, **changes: Any) -> 'Target':
        out = copy.copy(self)           # the real statistics and the memory shared
        vars(out).update(changes)
        return out

    def _chosen(self, kinds: Sequence[str] | None) -> list[int]:
        return [i for i, k in enumerate(self.kinds) if kinds is None or k in kinds]

    def of_kind(self, kind_: str) -> list[Recording]:
        return [self.recordings[i] for i in self._chosen((kind_,))]

    def simulate(self, effects: Sequence[Effect] = (), copies: int | None = None,
                 kinds: Sequence[str] | None = None, remember: bool = True) -> list[Repaired]:
        """Replays (repaired) of the recordings of ``kinds`` with ``effects`` and the given
        ones, the last ``REPLAYS`` remembered (unless ``remember`` is False)."""
        copies = self.copies if copies is None else copies
        effects = tuple(self.given) + tuple(effects)
        out = []
        for i in self._chosen(kinds):
            key = (i, self.config, effects, self.seed + 7919 * i, copies, self.base)
            make = functools.partial(self._replay, i, effects, copies)
            out.append(self.memory.replays.recall(key, make) if remember else make())
        return out

    def _replay(self, i: int, effects: tuple[Effect, ...], copies: int) -> Repaired:
        m = self.memory
        replayer = once(m.replayers, (i, self.config), lambda: Replayer(
            self.recordings[i], self.config, self.base, m.cache))
        sim = replayer.replay(effects, self.seed + 7919 * i, copies)
        hit = Repaired.of(sim, once(m.runs, (i, copies),       # the same for every replay
                                    lambda: dropouts.Runs(episodes(sim), len(sim))))
        hit.recording.readings.flags.writeable = False
        return hit

    def _stats(self, i: int, data: Repaired, replicates: int, seed: int) -> Stats:
        rec = data.recording
        if data.kind == 'closed_loop':
            every = self.config.task.perturb_every
            b = closedloop.blocks(rec, rec.readings, turns.sums(
                rec, rec.readings, every, lambda order, ep, m: converter.loop_sums(
                    rec.readings[order], data.marks[order], ep, m, self.loop_only)),
                every, self.loop_only)
        else:
            lay = once(self.memory.layouts, (i, len(rec) // len(self.recordings[i])),
                       lambda: stationary.Layout(rec, self.block_lengths[i]))
            used = rec.channels_used
            whole = used == list(range(rec.channels)) and rec.readings.flags.c_contiguous
            x = (rec.readings if whole else rec.readings[:, used]).astype(np.float64, copy=False)
            total = lay.by_block if replicates else lay.by_stratum   # no bootstrap: strata
            b = stationary.blocks(rec, x, lay, total, converter.stationary_sums(
                x, data.marks if whole else data.marks[:, used], lay.cell, lay.order, total))
        # the bootstrap weights of blocks like ``b``'s (every replay's), the last 8 kept
        w = self.memory.weights.recall((replicates, seed, b.edges.tobytes()), lambda: (
            bootstrap.weights(b, replicates, np.random.default_rng(seed)))) if replicates else None
        s = bootstrap.resampled(b, replicates, seed, w)
        with np.errstate(invalid='ignore', divide='ignore'):
            if b.kind == 'closed_loop':
                keys, cols = closedloop.stats(b, s, turns.with_stats(converter.loop_stats))
            else:
                keys, cols = stationary.stats(b, s)
                more_keys, more_cols = converter.stationary_stats(b, s)
                keys, cols = keys + more_keys, cols + more_cols
        values = np.concatenate([c if c.ndim == 2 else c[:, None] for c in cols], axis=1)
        return Stats(tuple(keys), values)

    def _simulated(self, effects: Sequence[Effect], replicates: int, kinds: Sequence[str] | None,
                   copies: int) -> tuple[Stats, Array]:
        """Simulated statistics of all copies together, and each one's ``_inflation``."""
        stats, factors = [], []
        for i, sim in zip(self._chosen(kinds), self.simulate(effects, copies, kinds)):
            s = self._stats(i, sim, replicates, self.seed + 101 + i)
            stats.append(s)
            factors.append(self._inflation(i, sim.recording, s, copies))
        return Stats.join(stats), np.concatenate(factors)

    def _inflation(self, i: int, sim: Recording, pooled: Stats, copies: int) -> Array:
        """Per statistic: 1, except a stationary cell level: the variance of the level between
        copies over the real bootstrap variance, pooled per condition, at least 1 (a slow
        wander moves whole runs, which blocks within a run cannot show); one copy: 1."""
        factor = np.ones(len(pooled.keys))
        if self.kinds[i] != 'stationary' or copies < 2:
            return factor
        by_unit, count, cells, cond, real_var, names = once(
            self.memory.plans, (i, copies), lambda: self._plan(i, sim, copies))
        x = sim.readings if self.channels == list(range(sim.channels)) else \
            sim.readings[:, self.channels]
        means = np.asarray(by_unit @ x).reshape(len(count), copies, x.shape[1])
        with np.errstate(invalid='ignore', divide='ignore'):
            means /= count[..., None]
            spread = np.var(means, axis=1, ddof=1)[cells]
            ok = np.isfinite(spread)
            a = np.bincount(cond[ok], spread[ok], minlength=len(names))
            b = np.bincount(cond[ok], real_var[ok], minlength=len(names))
            ratio = np.where(b > 0, np.clip(a / b, 1.0, 1e4), 1.0)
        known = self.memory.levels.get((i, copies))
        if known is None or known[0] != pooled.keys:       # the keys of most replays alike
            at = [j for j, k in enumerate(pooled.keys) if k.family == 'level']
            of = [names.get(pooled.keys[j].condition, len(names)) for j in at]
            known = self.memory.levels[(i, copies)] = (pooled.keys, np.array(at, np.int64),
                                                       np.array(of, np.int64))
        factor[known[1]] = np.r_[ratio, 1.0][known[2]]
        return factor

    def _plan(self, i: int, sim: Recording, copies: int) -> tuple[Any, ...]:
        """What ``_inflation`` needs of the protocol alone."""
        span = int(self.recordings[i].episode.max()) + 1
        labels, cell = stationary.cells(sim)
        code = cell * copies + sim.episode // span
        count = np.bincount(code, minlength=len(labels) * copies).reshape(len(labels), copies)
        real = self._real[i]
        names: dict[str | None, int] = {}
        entries = []
        for c, (condition, h) in enumerate(labels):
            part = None if h is None else f'heading {h:g} deg'
            for k, sensor in enumerate(self.channels):
                j = real.index.get(Key('level', (sensor,), condition, part))
                if j is not None:
                    entries.append((c, k, names.setdefault(condition, len(names)),
                                    real.variance[j]))
        e = np.array(entries, np.float64).reshape(-1, 4)
        by_unit = sparse.csr_matrix((np.ones(code.size), (code, np.arange(code.size))),
                                    shape=(len(labels) * copies, code.size))   # sums by unit
        return (by_unit, count, (e[:, 0].astype(int), e[:, 1].astype(int)), e[:, 2].astype(int),
                e[:, 3], names)

    # -- comparisons ----------------------------------------------------------------------

    def compare(self, effects: Sequence[Effect] = (), replicates: int | None = None) -> Comparison:
        """Real against simulated with ``effects``; rare counts by the count test; each
        made once (the stock simulator's is asked for by the world's parts and the scores)."""
        replicates = min(self.replicates, SIM_REPLICATES) if replicates is None else replicates
        key = (self.seed, self.config, tuple(self.given) + tuple(effects), replicates)
        return once(self.memory.comparisons, key, lambda: self._compare(effects, replicates))

    def _compare(self, effects: Sequence[Effect], replicates: int) -> Comparison:
        sim, factor = self._simulated(effects, replicates, None, self.copies)
        c = compare(self.real, sim, factor)
        if not any(FAMILIES[k.family].counted for k in c.keys):
            return c
        real, own = self.counts, dropouts.counts(self.simulate(effects))
        k = dropouts.count_copies(self.samples, self.copies)
        if k != self.copies and dropouts.undecided(real, own):      # a closer count
            own = dropouts.counts(self.simulate(effects, copies=k, remember=False))
        return recount(c, real, own)

    def objective(self, effects: Sequence[Effect] = (), kinds: Sequence[str] | None = None,
                  families: frozenset[str] | None = None, margin: float = MARGIN,
                  limits: bool = False) -> float:
        """The discrepancy with ``effects`` added, over ``kinds`` and ``families`` (None: all
        but the limits-only ones unless ``limits``); each value computed once."""
        key = (self.seed, self.config, tuple(self.given) + tuple(effects),
               None if kinds is None else tuple(kinds), families, margin, limits)
        return once(self.memory.objectives, key,
                    lambda: self._objective(effects, kinds, families, margin, limits))

    def _objective(self, effects: Sequence[Effect], kinds: Sequence[str] | None,
                   families: frozenset[str] | None, margin: float, limits: bool) -> float:
        chosen = tuple(self._chosen(kinds))
        real = once(self.memory.real, chosen, lambda: Stats.join([self._real[i] for i in chosen]))
        copies = 1 if self.samples >= SIM_SAMPLES / 2 else self.copies   # long: one copy
        sim, factor = self._simulated(effects, 0, kinds, copies)
        ri, si, floor = once(self.memory.pairs, (real.keys, sim.keys, families, limits),
                             lambda: _pairs(real, sim, families, limits))
        d = real.estimate[ri] - sim.estimate[si]
        se = np.sqrt(real.variance[ri] * factor[si] * (1.0 + 1.0 / copies) + floor)
        ok = np.isfinite(d) & np.isfinite(se)
        return discrepancy(np.clip(d[ok] / se[ok], -Z_CAP, Z_CAP), margin)

    def replicate_discrepancies(self, c: Comparison) -> Array:
        """Each real bootstrap replicate's discrepancy against the simulated side of ``c``."""
        rows = [self.real.index[k] for k in c.keys]
        return replicate_discrepancies(self.real.values[1:, rows], c)

    def evidence(self, c: Comparison | None) -> 'TargetEvidence':
        """What a fitter sees (``c``: the comparison with the simulator as given)."""
        return TargetEvidence(self, c)


class TargetEvidence:
    """``effects.base.Evidence`` of a target and its comparison with the simulator."""

    def __init__(self, target: Target, c: Comparison | None):
        self.target = target
        self.c = c if c is not None else Comparison([], *(np.zeros(0),) * 4)
        self.channels, self.kinds = list(target.channels), frozenset(target.kinds)
        self.given, self.observed_base = target.given, target.base == 'observed'
        self.samples = target.samples

    def rows(self, family: str) -> list[Row]:
        if family not in FAMILIES:
            raise KeyError(f'no statistic family {family!r}')
        return self.c.rows(family)

    def families(self, part: str | None = None) -> frozenset[str]:
        present = frozenset(k.family for k in self.target.real.keys)
        return present if part is None else present & of_part(part)

    def objective(self, effects: Sequence[Effect], kinds: tuple[str, ...] | None = None,
                  families: frozenset[str] | None = None, limits: bool = False) -> float:
        return self.target.objective(effects, kinds, families, limits=limits)

    def group_evidence(self, part: str) -> Array:
        t = self.target
        real = t.of_kind('stationary')
        if not real:
            return evidence.loop_group_evidence(self.rows, t.channels, part)
        sim = self._sim()
        return evidence.part_evidence(real, sim, len(t.channels), part,
                                      (self._cuts(real), self._cuts(sim)))

    def group_null(self, part: str) -> Array:
        t = self.target
        if not t.of_kind('stationary'):         # the comparison's own z: standard already
            return np.zeros((0, len(t.channels), len(t.channels)))
        sim = self._sim()
        draws = ([r.recording for r in t.with_seed(t.seed + NULL_SEED * (k + 1)).simulate(
            kinds=('stationary',), copies=1, remember=False)] for k in range(NULL_DRAWS))
        return once(t.memory.nulls, (part, t.seed, t.config, t.given), lambda: np.stack([
            evidence.part_evidence(null, sim, len(t.channels), part,
                                   (self._cuts(null), self._cuts(sim))) for null in draws]))

    def own_wander(self) -> dict[int, dict[str, Any]]:
        t = self.target
        real = t.of_kind('stationary')
        if not real:
            return {}
        replays = self._sim()
        sim = [evidence.Own(r, c) for r, c in zip(replays, self._cuts(replays))]

        def parts(shared_by: tuple[int, ...]) -> tuple[evidence.Parts, evidence.Parts]:
            mine = [once(t.memory.own, (i, shared_by),       # the real recordings' own parts
                         lambda: evidence.Own(rec).parts(shared_by))
                    for i, rec in enumerate(real)]
            return mine, [own.parts(shared_by) for own in sim]
        return evidence.wandering(parts, t.channels)

    def shared_change(self) -> dict[str, Any] | None:
        t = self.target
        real = t.of_kind('stationary')
        if t.base == 'observed' or not real:
            return None
        sim = self._sim()
        return evidence.shared_change(real, sim, t.channels, (self._cuts(real), self._cuts(sim)))

    def steady_rows(self, rows: list[Row], change: dict[str, Any]) -> list[Row]:
        return evidence.steady_rows(rows, self.target.of_kind('stationary'), change)

    def spread_cells(self, sensors: Sequence[int],
                     closed_loop: bool = False) -> list[tuple[float, float]]:
        real = self.target.real
        level = {(k.sensors, k.condition): v for k, v in zip(real.keys, real.estimate)
                 if k.family == 'closed_loop_level'}
        return evidence.spread_cells(self.rows, level, sensors, closed_loop)

    def converter(self) -> dict[str, Any]:
        t = self.target
        grains = self.rows('granularity') or self.rows('loop_granularity')
        return converter.evidence(t.real_data, t.simulate(), grains)

    def rescaled_dropout(self, effect: Effect, sensors: Sequence[int]) -> Effect:
        t = self.target
        real = dropouts.seen_share(t.real_data, sensors)
        sim = dropouts.seen_share(t.simulate([effect]), sensors)
        rate = dropouts.rescaled_rate(getattr(effect, 'dropout'), real, sim)
        return dataclasses.replace(effect, dropout=rate)  # type: ignore[call-arg]

    def delayed_sensors(self) -> tuple[int, ...]:
        return closedloop.delayed_sensors(self.target.of_kind('closed_loop'))

    def worlds(self) -> dict[str, Any]:
        t = self.target
        return {label: condition_world(rec, label, t.config.world) for rec in t.recordings
                for label in rec.conditions()}

    def turns(self) -> Array:
        t = self.target
        return turns.measured(t.of_kind('closed_loop'), t.of_kind('stationary'), t.config)

    def stationary_runs(self, simulated: bool) -> list[Array]:
        t = self.target
        recs = self._sim() if simulated else t.of_kind('stationary')
        return [rec.readings[r][:, t.channels].astype(np.float64)
                for rec, cut in zip(recs, self._cuts(recs)) for r in cut]

    def _sim(self) -> list[Recording]:
        return [r.recording for r in self.target.simulate(kinds=('stationary',))]

    def _cuts(self, recs: Sequence[Recording]) -> list[list[np.ndarray]]:
        """The ``runs`` of the stationary recordings or of their replays, made once: the same
        for every replay of as many copies (one copy: the recording's own index columns)."""
        t = self.target
        return [once(t.memory.cuts, (i, len(rec) // len(t.recordings[i])), lambda: runs(rec))
                for i, rec in zip(t._chosen(('stationary',)), recs)]


def _pairs(real: Stats, sim: Stats, families: frozenset[str] | None,
           limits: bool) -> tuple[AnyArray, AnyArray, Array]:
    """(real, simulated) indices of the statistics an objective reads, and their floors: the
    same for every replay of the protocol."""
    only = having('limits')
    pairs = [(i, sim.index[k]) for i, k in enumerate(real.keys) if k in sim.index and (
        k.family in families if families is not None else limits or k.family not in only)]
    ri, si = (np.array(p, np.int64) for p in zip(*pairs)) if pairs else \
        (np.zeros(0, np.int64),) * 2
    return ri, si, floors([real.keys[i] for i in ri])
