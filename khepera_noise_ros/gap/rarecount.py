"""Rare counts (dropouts) judged by a count model, not by the bootstrap.

A statistic that counts rare events (a dropout share: a few readings in thousands) is
a Poisson count on each side.  Its bootstrap error bar is about the root of the real
count, and the simulator's count, near zero on a few copies, is known only roughly:
seven dropouts against none then lies three error bars off, which Holm's correction
over hundreds of statistics calls chance.  Here the count is compared exactly: given
the total count of both sides, the real one is binomial with the real side's share of
the readings under "same rate" (the conditional test for two Poisson rates), and the
simulated side gets many more readings (``COUNT_SAMPLES``) so that its rate is known
well (only when there are real events and the comparison's own copies give few
simulated ones).  The test's p-value gives the statistic's z, and its error bar is the
difference over that z (the pooled count's own, floored at one count, where they agree), so
the discrepancy, the held-out reduction and the bootstrap replicates see the count as
the count model does.  Zero on both sides is no evidence either way (z 0).
"""
from __future__ import annotations

import copy

import numpy as np
from scipy import stats as sps

from . import dropout, replay
from .blocks import Key
from .where import Z_CAP, Comparison

FAMILIES = dropout.FAMILIES
COUNT_SAMPLES = 48_000      # simulated readings per sensor aimed at for the counts
MAX_COPIES = 20             # ... with at most this many copies of the recordings
KNOWN = 20                  # simulated events that make the simulator's rate known
EVENTS = 2                  # real events that more simulated copies can make evidence of
EXACT = 1 << 24             # marks summed in single precision are exact counts below this


def counts(recordings: list) -> dict:
    """{Key: [count, readings]} of the dropout statistics of ``recordings`` (prepared by
    ``dropout.prepared``: their marks are known), summed over recordings with equal keys:
    per sensor and end, and pooled over the sensors, as ``dropout.shares`` names them."""
    out: dict = {}
    for rec in recordings:
        done = dropout.known(rec.readings)
        if done is None:
            rec = dropout.prepared(rec)
            done = dropout.known(rec.readings)
        marks = done[0]
        if replay.kind(rec) == 'closed_loop':
            family, channels = 'closed_loop_dropout', tuple(range(min(8, marks.shape[1])))
            groups = [(str(c), rec.condition == c) for c in np.unique(rec.condition)]
        else:
            family, channels = 'dropout', tuple(rec.channels_used)
            groups = [(None, slice(None))]
        for condition, rows in groups:
            # 0/1 marks: sums of fewer than 2 ** 24 are exact counts, whichever are added
            # first, so all channels are summed in place and then picked (no copy)
            hit = marks[rows].sum(axis=0)[list(channels)] if marks.shape[0] < EXACT \
                else marks[rows][:, list(channels)].sum(axis=0)        # (C, 2)
            n = float(np.count_nonzero(rows) if condition is not None else marks.shape[0])
            for key, value in dropout.shares(family, channels, condition, hit[None] / n):
                pooled = len(key.sensors) > 1
                total = _add(out, key)
                total[0] += float(value[0]) * n * (len(channels) if pooled else 1)
                total[1] += n * (len(channels) if pooled else 1)
    for v in out.values():
        v[0] = float(np.round(v[0]))
    return out


def _add(table: dict, key: Key) -> list:
    if key not in table:
        table[key] = [0.0, 0.0]
    return table[key]


def test(r: float, n_r: float, s: float, n_s: float) -> tuple[float, float]:
    """(z, standard error of the difference in shares) of ``r`` events in ``n_r`` real
    readings against ``s`` in ``n_s`` simulated ones: the two-sided conditional binomial
    test of equal rates, as a normal z; 0 when neither side has any."""
    k = r + s
    d = r / n_r - s / n_s
    # the pooled rate's standard error, at least one count's worth
    pooled = max(k, 1.0) / (n_r + n_s)
    se0 = float(np.sqrt(pooled * (1.0 / n_r + 1.0 / n_s)))
    if k <= 0:
        return 0.0, se0
    f = n_r / (n_r + n_s)
    upper = sps.binom.sf(r - 1, k, f)            # P(R >= r)
    lower = sps.binom.cdf(r, k, f)               # P(R <= r)
    p = min(1.0, 2.0 * min(upper, lower))
    z = float(min(sps.norm.isf(p / 2.0), Z_CAP)) * (1.0 if d >= 0 else -1.0)
    if abs(z) < 1e-9 or abs(d) <= 0:
        return 0.0, se0
    return z, abs(d) / abs(z)


def recount(c: Comparison, real: dict, sim: dict) -> Comparison:
    """``c`` with the statistics counted in both ``real`` and ``sim`` ({Key: [count,
    readings]}) judged by ``test``: their shares, z and error bars replaced."""
    rows = [i for i, k in enumerate(c.keys) if k.family in FAMILIES and k in real
            and k in sim and real[k][1] > 0 and sim[k][1] > 0]
    if not rows:
        return c
    out = copy.copy(c)
    out.real, out.sim, out.se, out.z = (np.array(v, np.float64) for v in
                                        (c.real, c.sim, c.se, c.z))
    for i in rows:
        (r, n_r), (s, n_s) = real[c.keys[i]], sim[c.keys[i]]
        z, se = test(r, n_r, s, n_s)
        out.real[i], out.sim[i], out.se[i], out.z[i] = r / n_r, s / n_s, se, z
    return out


def copies(target) -> int:
    """Copies of the recordings simulated for the counts: the comparison's own when they
    hold half of ``COUNT_SAMPLES`` readings per sensor (a long recording: a rare rate
    gives many counts there, and more replays would cost time), else ``COUNT_SAMPLES``
    readings (at most ``MAX_COPIES`` copies)."""
    n = max(sum(len(r) for r in target.recordings), 1)
    if n * target.copies >= COUNT_SAMPLES / 2:
        return int(target.copies)
    return int(max(target.copies, min(MAX_COPIES, np.ceil(COUNT_SAMPLES / n))))


def compare(target, c: Comparison, effects=()) -> Comparison:
    """``c``, a comparison of ``target`` against the simulator with ``effects``, with its
    dropout statistics judged by counts against ``copies`` simulated copies (the
    comparison's own replays when those are as many)."""
    if not any(k.family in FAMILIES for k in c.keys):
        return c
    real, own = counts(target.recordings), counts(target.simulate(effects))
    k = copies(target)
    if k == target.copies or not _undecided(real, own):
        return recount(c, real, own)
    # not kept among the remembered replays: the fitters' replays stay there
    return recount(c, real, counts(target.simulate(effects, copies=k, remember=False)))


def _undecided(real: dict, sim: dict) -> bool:
    """Do the comparison's own copies leave a count to be judged on more: ``EVENTS`` or more
    real events beside fewer than ``KNOWN`` simulated ones?  Fewer real events are no
    evidence however many copies (one against none at 1:20 is z 1.7, inside the
    discrepancy's margin of 2); with many simulated ones their rate is known already."""
    return any(r >= EVENTS and sim[key][0] < KNOWN for key, (r, _) in real.items()
               if key in sim)
