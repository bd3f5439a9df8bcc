"""Dropouts: isolated readings stuck at a sensor's lowest or highest value.

``gap.dropout`` marks a reading at a sensor's extreme value lying far from the median
of its neighbours in the run (stationary runs and closed-loop episodes alike).  A
sensor has dropouts when its real count exceeds the simulator's expected count by
``Z`` Poisson standard errors; sensors dropping out to the same value are also
pooled, so a small rate shared by many sensors is found when each has few.
"""
from __future__ import annotations

import dataclasses
from collections import Counter

import numpy as np

from . import dropout

Z = 4.0
MIN_HITS = 3
MAX_RATE = 0.5


def _counts(rec, sensors) -> tuple[np.ndarray, np.ndarray, list]:
    """(hits (C, 2), readings (C,), values [(low, high)] per sensor) of one recording
    (its dropouts as ``dropout.prepared`` found them)."""
    done = dropout.known(rec.readings)
    if done is None:
        rec = dropout.prepared(rec)
        done = dropout.known(rec.readings)
    marks, ends = done
    counted = np.isfinite(rec.readings[:, sensors]).sum(axis=0).astype(np.float64)
    return marks[:, sensors].sum(axis=0), counted, [tuple(ends[s]) for s in sensors]


def dropouts(real: list, sim: list) -> dict:
    """{sensor: (value, rate)} of the sensors with more isolated extreme readings than
    the simulator gives; ``sim``: the simulator's replays of ``real``, in order (any
    number of copies each)."""
    if not real:
        return {}
    sensors = list(real[0].channels_used)
    hits = np.zeros((len(sensors), 2))
    total = np.zeros(len(sensors))
    expected = np.zeros((len(sensors), 2))
    var = np.zeros((len(sensors), 2))
    votes = [[Counter(), Counter()] for _ in sensors]
    for i, rec in enumerate(real):
        h, n, values = _counts(rec, sensors)
        hits += h
        total += n
        for k, v in enumerate(values):
            for end in (0, 1):
                if h[k, end]:
                    votes[k][end][float(v[end])] += h[k, end]
        if i < len(sim):
            hs, ns, _ = _counts(sim[i], sensors)
            copies = max(1.0, ns.max() / max(n.max(), 1.0))
            with np.errstate(invalid='ignore', divide='ignore'):
                e = np.where(ns[:, None] > 0, hs / ns[:, None] * n[:, None], 0.0)
            expected += e
            var += e + 1.0 / copies         # Poisson, and the simulator's own count
    out: dict = {}
    for end in (0, 1):
        excess = hits[:, end] - expected[:, end]
        alone = (hits[:, end] >= MIN_HITS) & (excess > Z * np.sqrt(var[:, end]))
        for k in np.flatnonzero(alone):
            _keep(out, sensors[k], votes[k][end], excess[k] / total[k])
        # pooled over the sensors with any hit at the same value
        by_value: dict = {}
        for k in np.flatnonzero(hits[:, end] > 0):
            by_value.setdefault(votes[k][end].most_common(1)[0][0], []).append(k)
        for value, ks in by_value.items():
            ks = np.array(ks)
            if hits[ks, end].sum() >= MIN_HITS and len(ks) > 1 and \
                    excess[ks].sum() > Z * np.sqrt(var[ks, end].sum()):
                rate = float(excess[ks].sum() / total[ks].sum())
                for k in ks:
                    if sensors[k] not in out:
                        out[sensors[k]] = (value, rate)
    return out


def _keep(out: dict, sensor: int, votes: Counter, rate: float) -> None:
    value = votes.most_common(1)[0][0]
    if sensor not in out or rate > out[sensor][1]:
        out[sensor] = (value, float(rate))


def rescaled(target, effect, sensors) -> object:
    """``effect`` with its dropout rate scaled by the real over the simulated share of
    dropouts on ``sensors``: a dropout near its run's level is not seen, on either side,
    so the share seen understates the rate by the same factor in both."""
    seen = []
    for recs in (target.recordings, target.simulate([effect])):
        hits = total = 0.0
        for rec in recs:
            h, n, _ = _counts(rec, list(rec.channels_used))
            used = [list(rec.channels_used).index(s) for s in sensors]
            hits += h[used].sum()
            total += n[used].sum()
        seen.append(hits / max(total, 1.0))
    if seen[1] <= 0:
        return effect
    rate = float(np.clip(effect.dropout * seen[0] / seen[1], effect.dropout, MAX_RATE))
    return dataclasses.replace(effect, dropout=round(rate, 5))
