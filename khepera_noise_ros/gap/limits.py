"""Dropouts: isolated readings stuck at zero or at a limit of the reading range.

A reading equal to an end of the range (0 or the scale's top) in a run whose
median lies well away from it (by ``AWAY`` readings and ``SPREADS`` robust sds) is a
dropout: the sensor
lost one sample, it did not see that light.  A sensor has dropouts when its real
count exceeds the simulator's expected count by ``Z`` Poisson standard errors.
"""
from __future__ import annotations

import numpy as np

from . import replay

AWAY = 10.0
SPREADS = 6.0
Z = 4.0


def _counts(recs, sensors, value: float) -> tuple[np.ndarray, np.ndarray]:
    """Readings at ``value`` in runs whose bulk lies far from it: by ``AWAY`` readings and
    by ``SPREADS`` robust sds (a noisy run near the end of the range clips there; that
    is a limit, not a dropout)."""
    hits = np.zeros(len(sensors))
    total = np.zeros(len(sensors))
    for rec in recs:
        for r in replay.runs(rec):
            x = rec.readings[r][:, sensors]
            median = np.median(x, axis=0)
            sd = 1.4826 * np.median(np.abs(x - median), axis=0)
            far = np.abs(median - value) >= np.maximum(AWAY, SPREADS * sd)
            hits += np.where(far, (x == value).sum(axis=0), 0)
            total += np.where(far, x.shape[0], 0)
    return hits, total


def dropouts(real: list, sim: list, limits) -> dict:
    """{sensor: (value, rate)} of the sensors with more isolated end readings than the
    simulator gives (``real``, ``sim``: stationary recordings)."""
    if not real:
        return {}
    sensors = list(real[0].channels_used)
    copies = max(1, round(sum(len(s) for s in sim) / max(1, sum(len(r) for r in real))))
    out: dict = {}
    for value in sorted(set(float(v) for v in limits)):
        hr, nr = _counts(real, sensors, value)
        hs, ns = _counts(sim, sensors, value) if sim else (np.zeros(len(sensors)),) * 2
        with np.errstate(invalid='ignore', divide='ignore'):
            expected = np.where(ns > 0, hs / ns * nr, 0.0)
        for k, s in enumerate(sensors):
            if hr[k] >= 3 and hr[k] > expected[k] + Z * np.sqrt(expected[k] + 1.0 / copies):
                rate = float((hr[k] - expected[k]) / nr[k])
                if s not in out or rate > out[s][1]:
                    out[s] = (value, rate)
    return out
