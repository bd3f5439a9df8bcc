"""One set of real recordings held against the simulator, with or without added effects.

A ``Target`` computes the real statistics once (with bootstrap replicates) and
replays the recordings' protocols in the simulator on demand.  ``compare``
gives the full comparison (bootstrap variance on both sides); ``objective``
is the cheap version used while fitting: simulated estimates only, with the
simulated variance taken as the real one divided by the number of simulated
copies, and common random numbers (a fixed seed) so that the objective is a
deterministic function of the effect's parameters.
"""
from __future__ import annotations

import copy
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from ..recording import Recording
from . import dropout, rarecount, replay, statistics
from .simconfig import SimConfig
from .statistics import Stats
from .where import MARGIN, Z_CAP, Comparison, compare, discrepancy, squared_floors

SIM_COPIES = 3
SIM_REPLICATES = 60      # bootstrap replicates of the simulated side in ``compare``
SIM_SAMPLES = 20_000    # simulated samples aimed at when choosing the number of copies
# The pile at a sensor's ends (``gap.pileup``) locates and scores limits; its bootstrap
# error ignores where an end falls, which a slow change moves, so only a limit is fitted
# to it.  So are isolated readings at a sensor's extremes (``gap.dropout``).
LIMITS_ONLY = frozenset({'pileup', 'dropout', 'closed_loop_dropout'})


@dataclass
class Target:
    recordings: list[Recording]
    config: SimConfig
    seed: int = 0
    base: str = 'auto'
    copies: int | None = None     # simulated copies of the recordings; None: by size
    replicates: int = statistics.REPLICATES
    block_lengths: list[int] = field(default_factory=list)
    given: tuple = ()             # effects already chosen: the simulator always has them
    real: Stats = field(init=False)
    kinds: list[str] = field(init=False)

    def __post_init__(self):
        # dropouts repaired once, remembered for their own statistics and fit: every
        # other statistic and fitter sees the repaired readings (``gap.dropout``)
        self.recordings = [dropout.prepared(r) for r in self.recordings]
        if self.copies is None:       # enough simulated samples, not more: fits cost less
            n = sum(len(r) for r in self.recordings)
            self.copies = int(np.clip(round(SIM_SAMPLES / max(n, 1)), 2, SIM_COPIES))
        if not self.block_lengths:
            self.block_lengths = [_block_length(r) for r in self.recordings]
        self.kinds = [replay.kind(r) for r in self.recordings]
        # closed loop alone: its value statistics stand in for the stationary ones
        self.loop_only = 'stationary' not in self.kinds
        self._real = [statistics.compute(_blocks(rec, n, self.config, self.loop_only),
                                         self.replicates,
                                         self.seed + i)
                      for i, (rec, n) in enumerate(zip(self.recordings, self.block_lengths))]
        self.real = _join(self._real)
        self._objectives = {}     # objective values, shared with ``with_given`` copies
        self.own_parts = {}       # the real recordings' own-wander parts (``gap.ownwander``)

    def _chosen(self, kinds) -> list[int]:
        return [i for i, k in enumerate(self.kinds) if kinds is None or k in kinds]

    def of_kind(self, kind: str) -> list[Recording]:
        """The (dropout-repaired) recordings of one protocol, 'stationary' or 'closed_loop'."""
        return [self.recordings[i] for i in self._chosen((kind,))]

    def simulate(self, effects=(), copies: int | None = None, kinds=None,
                 remember: bool = True) -> list[Recording]:
        """Replays of the recordings of ``kinds`` with ``effects`` (and the given ones);
        ``remember=False``: not kept among the remembered replays (``_replay``)."""
        copies = self.copies if copies is None else copies
        effects = tuple(self.given) + tuple(effects)
        return [_replay(self.recordings[i], self.config, effects, self.seed + 7919 * i,
                        copies, self.base, remember) for i in self._chosen(kinds)]

    def sim_stats(self, effects=(), replicates: int = 0, kinds=None) -> Stats:
        return self._simulated(effects, replicates, kinds)[0]

    def _simulated(self, effects, replicates: int, kinds,
                   copies: int | None = None) -> tuple[Stats, np.ndarray]:
        """Simulated statistics of all copies together, and per statistic the factor by
        which the block bootstrap understates the variance of cell levels (see
        ``_level_inflation``)."""
        copies = self.copies if copies is None else copies
        stats, factors = [], []
        for i, sim in zip(self._chosen(kinds), self.simulate(effects, copies, kinds)):
            s = statistics.compute(_blocks(sim, self.block_lengths[i], self.config, self.loop_only,
                                           replicates == 0),
                                   replicates, self.seed + 101 + i)
            stats.append(s)
            factors.append(self._level_inflation(i, sim, s, copies))
        return _join(stats), np.concatenate(factors)

    def _level_inflation(self, i: int, sim: Recording, pooled: Stats,
                         copies: int) -> np.ndarray:
        """Per statistic of ``pooled``: 1, except cell levels of stationary data.

        A slow wander moves whole runs, which blocks within a run cannot show.  The
        copies of the simulation are independent replays, so the spread of a level
        between copies is its true sampling variance under the simulated model; its
        ratio to the real data's bootstrap variance, pooled over the levels of a
        condition, scales the variance of those levels on both sides (never below 1).
        Cell means per copy come straight from the readings (one pass, no statistics).
        """
        factor = np.ones(len(pooled.keys))
        if self.kinds[i] != 'stationary' or copies < 2:
            return factor
        plan = self._inflation_plan(i, sim, copies)
        code, size, count, cells, cond, real_var, names = plan
        x = sim.readings[:, list(self.recordings[i].channels_used)]
        means = np.stack([np.bincount(code, x[:, k], minlength=size) for k in range(x.shape[1])],
                         axis=1).reshape(len(count), copies, x.shape[1])
        with np.errstate(invalid='ignore', divide='ignore'):
            means /= count[..., None]
        spread = np.var(means, axis=1, ddof=1)[cells]             # per (cell, channel) entry
        ok = np.isfinite(spread)
        # sums over the entries in order, as a loop adding them one by one would
        a = np.bincount(cond[ok], spread[ok], minlength=len(names))
        b = np.bincount(cond[ok], real_var[ok], minlength=len(names))
        with np.errstate(invalid='ignore', divide='ignore'):
            ratio = np.where(b > 0, np.clip(a / b, 1.0, 1e4), 1.0)
        at, of = self._level_positions(i, pooled.keys, names)
        factor[at] = np.r_[ratio, 1.0][of]
        return factor

    def _inflation_plan(self, i: int, sim: Recording, copies: int) -> tuple:
        """What ``_level_inflation`` needs of the protocol alone (the same for every replay
        with ``copies`` copies): sample codes of (cell, copy), counts, and the (cell,
        channel) entries that have a real level, with their condition and real variance."""
        cache = self.__dict__.setdefault('_plans', {})
        key = (i, copies)
        if key not in cache:
            span = int(self.recordings[i].episode.max()) + 1
            lay = statistics._layout(sim, self.block_lengths[i])
            labels, cell = lay['labels'], lay['cell']
            code = cell * copies + sim.episode // span
            size = len(labels) * copies
            count = np.bincount(code, minlength=size).reshape(len(labels), copies)
            used = list(self.recordings[i].channels_used)
            real = self._real[i]
            real_index = real.index()
            names: dict = {}
            entries = []
            for c, (condition, h) in enumerate(labels):
                part = None if h is None else f'heading {h:g} deg'
                for k, sensor in enumerate(used):
                    j = real_index.get(statistics.Key('level', (sensor,), condition, part))
                    if j is not None:
                        entries.append(((c, k), names.setdefault(condition, len(names)),
                                        real.variance[j]))
            cells = tuple(np.array([e[0][d] for e in entries], np.int64) for d in (0, 1))
            cache[key] = (code, size, count, cells, np.array([e[1] for e in entries], np.int64),
                          np.array([e[2] for e in entries], np.float64), names)
        return cache[key]

    def _level_positions(self, i: int, keys: list,
                         names: dict) -> tuple[np.ndarray, np.ndarray]:
        """(positions of the level statistics in ``keys``, their condition's number in
        ``names``, len(names) if none), cached for a key list shared by replays."""
        cache = self.__dict__.setdefault('_positions', {})
        hit = cache.get((i, id(keys)))
        if hit is None or hit[0] is not keys:
            if len(cache) > 32:
                cache.clear()
            at = [j for j, k in enumerate(keys) if k.family == 'level']
            of = [names.get(keys[j].condition, len(names)) for j in at]
            hit = cache[(i, id(keys))] = (keys, np.array(at, np.int64),
                                          np.array(of, np.int64))
        return hit[1], hit[2]

    def with_given(self, effects) -> 'Target':
        """This target with ``effects`` always in the simulator (real statistics shared):
        a candidate fitted against it is fitted jointly with them."""
        out = copy.copy(self)
        out.given = tuple(effects)
        return out

    def compare(self, effects=(), replicates: int | None = None) -> Comparison:
        """Real against simulated-with-``effects``, bootstrap variance on both sides (the
        simulated side, 2-3 copies, is the more precise: ``SIM_REPLICATES`` suffice)."""
        replicates = min(self.replicates, SIM_REPLICATES) if replicates is None else replicates
        sim, factor = self._simulated(effects, replicates, None)
        # dropout shares: rare counts, judged by a count model (``gap.rarecount``)
        return rarecount.compare(self, compare(self.real, sim, factor), effects)

    def objective(self, effects=(), kinds=None, families=None, margin=MARGIN,
                  limits=False) -> float:
        """The discrepancy with ``effects`` added, from simulated estimates only, over the
        recordings of ``kinds`` and the statistics of ``families`` (None: all but those
        in ``LIMITS_ONLY`` unless ``limits``).  A deterministic function of its arguments
        and the target (common random numbers), so each value is computed once: a
        bounded search asks for the same clipped, rounded parameters again."""
        key = (id(self.real), self.seed, self.config, self.base, self.copies,
               tuple(self.block_lengths), tuple(self.given) + tuple(effects), kinds,
               None if families is None else frozenset(families), margin, limits)
        memo = self._objectives
        try:
            return memo[key]
        except KeyError:
            pass
        except TypeError:           # an unhashable parameter: computed every time
            return self._objective(effects, kinds, families, margin, limits)
        memo[key] = value = self._objective(effects, kinds, families, margin, limits)
        return value

    def _objective(self, effects, kinds, families, margin, limits) -> float:
        real = self._real_of(kinds)
        copies = self._objective_copies()
        sim, factor = self._simulated(effects, 0, kinds, copies)
        ri, si, floor = self._pairs(real, sim, families, limits)
        d = real.estimate[ri] - sim.estimate[si]
        se = np.sqrt(real.variance[ri] * factor[si] * (1.0 + 1.0 / copies) + floor)
        ok = np.isfinite(d) & np.isfinite(se)
        return discrepancy(np.clip(d[ok] / se[ok], -Z_CAP, Z_CAP), margin)

    def _real_of(self, kinds) -> Stats:
        """The real statistics of the recordings of ``kinds``, joined once."""
        cache = self.__dict__.setdefault('_joined', {})
        if kinds not in cache:
            cache[kinds] = _join([self._real[i] for i in self._chosen(kinds)])
        return cache[kinds]

    def _pairs(self, real: Stats, sim: Stats, families, limits: bool) -> tuple:
        """(real rows, simulated rows, squared floor of the standard error) of the
        statistics an objective compares; cached while the simulated key list is the
        one every replay of the protocol shares."""
        cache = self.__dict__.setdefault('_aligned', {})
        key = (id(real.keys), id(sim.keys), None if families is None else frozenset(families),
               limits)
        hit = cache.get(key)
        if hit is None or hit[0] is not real.keys or hit[1] is not sim.keys:
            where = sim.index()
            pairs = [(i, where[k]) for i, k in enumerate(real.keys) if k in where
                     and (k.family in families if families is not None
                          else limits or k.family not in LIMITS_ONLY)]
            ri, si = (np.array(p, np.int64) for p in zip(*pairs))
            floor = squared_floors([real.keys[i] for i in ri])
            if len(cache) > 32:
                cache.clear()
            hit = cache[key] = (real.keys, sim.keys, ri, si, floor)
        return hit[2:]

    def _objective_copies(self) -> int:
        """Copies simulated while fitting: one for a long recording (its simulated
        statistics are then as precise as the real ones, which the objective allows
        for), else as many as for comparisons."""
        n = sum(len(r) for r in self.recordings)
        return 1 if n >= SIM_SAMPLES / 2 else self.copies

    def replicate_discrepancies(self, c: Comparison) -> np.ndarray:
        """Discrepancy of each bootstrap replicate of the real data against the simulated
        side of ``c`` (a comparison of this target)."""
        index = self.real.index()
        rows = [index[k] for k in c.keys]
        with np.errstate(divide='ignore', invalid='ignore'):
            z = (self.real.values[1:, rows] - c.sim[None]) / c.se[None]
        z = np.nan_to_num(z, nan=0.0, posinf=1e3, neginf=-1e3)
        return (np.clip(np.abs(z) - 2.0, 0.0, None) ** 2).sum(axis=1)


_REPLAYS: OrderedDict = OrderedDict()
REPLAY_CACHE = 16


def _replay(rec: Recording, config: SimConfig, effects: tuple, seed: int, copies: int,
            base: str, remember: bool = True) -> Recording:
    """``replay.replay`` with its dropouts repaired (``dropout.prepared``), remembered: a
    replay is a deterministic function of the recording, the configuration, the effects,
    the seed and the copies, and the fitters ask for the same one again (the simulator
    with the chosen effects and nothing more).  A replay given out is read-only, since
    it is shared.  ``remember=False`` (a one-off, e.g. many copies for a count): neither
    looked up nor kept, so the fitters' replays stay."""
    key = (id(rec), config, effects, seed, copies, base)
    try:
        hit = _REPLAYS.get(key) if remember else None
    except TypeError:           # an unhashable parameter: replay it every time
        hit, remember = None, False
    if hit is not None and hit[0] is rec:
        _REPLAYS.move_to_end(key)
        return hit[1]
    raw = replay.replay(rec, config, effects, seed=seed, replicates=copies, base=base)
    if not remember:
        return dropout.prepared(raw)
    raw.readings.flags.writeable = False
    sim = dropout.prepared(raw)       # repaired once, not again when asked again
    sim.readings.flags.writeable = False
    _REPLAYS[key] = (rec, sim)
    if len(_REPLAYS) > REPLAY_CACHE:
        _REPLAYS.popitem(last=False)
    return sim


def _join(parts: list[Stats]) -> Stats:
    out = parts[0]
    for p in parts[1:]:
        out = out + p
    return out


def _block_length(rec: Recording) -> int:
    if replay.kind(rec) == 'closed_loop':
        return 0
    return statistics.block_length(rec, rec.channels_used)


def _blocks(rec: Recording, length: int, config: SimConfig,
            loop_only: bool = False, column_major: bool = False) -> statistics.Blocks:
    """The block sums of ``rec``; ``loop_only``: no stationary recording beside it
    (``closed_loop_blocks``); ``column_major``: only the full data's sums are wanted (no
    replicates), which are added faster down contiguous columns."""
    if replay.kind(rec) == 'closed_loop':
        return statistics.closed_loop_blocks(rec, config.task.perturb_every, loop_only)
    return statistics.stationary_blocks(rec, rec.channels_used, length, column_major)
