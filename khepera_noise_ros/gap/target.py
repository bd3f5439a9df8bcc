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
from dataclasses import dataclass, field

import numpy as np

from ..recording import Recording
from . import dropout, replay, statistics
from .simconfig import SimConfig
from .statistics import Stats
from .where import MARGIN, Z_CAP, Comparison, compare, discrepancy, standard_error

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
        self._real = [statistics.compute(_blocks(rec, n, self.config), self.replicates,
                                         self.seed + i)
                      for i, (rec, n) in enumerate(zip(self.recordings, self.block_lengths))]
        self.real = _join(self._real)

    def _chosen(self, kinds) -> list[int]:
        return [i for i, k in enumerate(self.kinds) if kinds is None or k in kinds]

    def simulate(self, effects=(), copies: int | None = None, kinds=None) -> list[Recording]:
        copies = self.copies if copies is None else copies
        effects = tuple(self.given) + tuple(effects)
        out = [replay.replay(self.recordings[i], self.config, effects,
                             seed=self.seed + 7919 * i, replicates=copies, base=self.base)
               for i in self._chosen(kinds)]
        return [dropout.prepared(r) for r in out]

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
            s = statistics.compute(_blocks(sim, self.block_lengths[i], self.config),
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
        span = int(self.recordings[i].episode.max()) + 1
        lay = statistics._layout(sim, self.block_lengths[i])
        labels, cell = lay['labels'], lay['cell']
        copy = sim.episode // span
        used = list(self.recordings[i].channels_used)
        code = cell * copies + copy
        size = len(labels) * copies
        count = np.bincount(code, minlength=size).reshape(len(labels), copies)
        x = sim.readings[:, used]
        means = np.stack([np.bincount(code, x[:, k], minlength=size) for k in range(len(used))],
                         axis=1).reshape(len(labels), copies, len(used))
        with np.errstate(invalid='ignore', divide='ignore'):
            means /= count[..., None]
        spread = np.var(means, axis=1, ddof=1)                    # (cells, channels)
        real = self._real[i]
        real_index = real.index()
        by_condition: dict = {}
        for c, (cond, h) in enumerate(labels):
            part = None if h is None else f'heading {h:g} deg'
            for k, sensor in enumerate(used):
                key = statistics.Key('level', (sensor,), cond, part)
                if key in real_index and np.isfinite(spread[c, k]):
                    acc = by_condition.setdefault(cond, [0.0, 0.0])
                    acc[0] += spread[c, k]
                    acc[1] += real.variance[real_index[key]]
        ratio = {c: float(np.clip(a / b, 1.0, 1e4)) if b > 0 else 1.0
                 for c, (a, b) in by_condition.items()}
        for j, key in enumerate(pooled.keys):
            if key.family == 'level':
                factor[j] = ratio.get(key.condition, 1.0)
        return factor

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
        return compare(self.real, sim, factor)

    def objective(self, effects=(), kinds=None, families=None, margin=MARGIN,
                  limits=False) -> float:
        """The discrepancy with ``effects`` added, from simulated estimates only, over the
        recordings of ``kinds`` and the statistics of ``families`` (None: all but those
        in ``LIMITS_ONLY`` unless ``limits``)."""
        real = _join([self._real[i] for i in self._chosen(kinds)])
        copies = self._objective_copies()
        sim, factor = self._simulated(effects, 0, kinds, copies)
        where = sim.index()
        pairs = [(i, where[k]) for i, k in enumerate(real.keys) if k in where
                 and (k.family in families if families is not None
                      else limits or k.family not in LIMITS_ONLY)]
        ri, si = (np.array(p, np.int64) for p in zip(*pairs))
        d = real.estimate[ri] - sim.estimate[si]
        se = standard_error(real.variance[ri] * factor[si] * (1.0 + 1.0 / copies),
                            [real.keys[i] for i in ri])
        ok = np.isfinite(d) & np.isfinite(se)
        return discrepancy(np.clip(d[ok] / se[ok], -Z_CAP, Z_CAP), margin)

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


def _join(parts: list[Stats]) -> Stats:
    out = parts[0]
    for p in parts[1:]:
        out = out + p
    return out


def _block_length(rec: Recording) -> int:
    if replay.kind(rec) == 'closed_loop':
        return 0
    return statistics.block_length(rec, rec.channels_used)


def _blocks(rec: Recording, length: int, config: SimConfig) -> statistics.Blocks:
    if replay.kind(rec) == 'closed_loop':
        return statistics.closed_loop_blocks(rec, config.task.perturb_every)
    return statistics.stationary_blocks(rec, rec.channels_used, length)
