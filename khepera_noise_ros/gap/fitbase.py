"""What every effect's fitter shares: the ``Candidate`` it returns, the detection
threshold, a comparison's rows of one family, and a golden-section search.  Its own
module so that fitters kept in modules of their own (``gap.fitturn``) need not import
``gap.fit``, which registers them."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .where import Comparison

Z_DETECT = 4.0          # a fingerprint statistic must lie this many standard errors out


@dataclass
class Candidate:
    name: str
    effect: object | None     # None: nothing to add (see ``note``)
    note: str
    given: list | None = None  # the chosen effects as refitted with it (``compound``)


def rows(c: Comparison, family: str):
    """(key, real, sim, se, z) of the statistics of ``family``; the comparison is split
    by family once (fitters ask for many families, many times)."""
    by = c.__dict__.get('_by_family')
    if by is None:
        by = {}
        for row in zip(c.keys, c.real, c.sim, c.se, c.z):
            by.setdefault(row[0].family, []).append(row)
        c.__dict__['_by_family'] = by
    return list(by.get(family, ()))


def golden(f, lo: float, hi: float, evaluations: int) -> float:
    """Minimiser of f on [lo, hi] by golden-section search."""
    g = (math.sqrt(5) - 1) / 2
    a, b = lo, hi
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = f(c), f(d)
    for _ in range(max(0, evaluations - 2)):
        if fc <= fd:
            b, d, fd = d, c, fc
            c = b - g * (b - a)
            fc = f(c)
        else:
            a, c, fc = c, d, fd
            d = a + g * (b - a)
            fd = f(d)
    return c if fc <= fd else d


def channels(target) -> list[int]:
    """The channels a target's recordings use."""
    return list(target.recordings[0].channels_used)


def names(sensors) -> str:
    return ', '.join(f's{s}' for s in sensors)


def by_condition(c: Comparison, family: str) -> dict:
    """{condition: {sensor: (rms real, rms simulated)}} over a family's cells."""
    acc: dict = {}
    for k, r, s, *_ in rows(c, family):
        acc.setdefault(k.condition, {}).setdefault(k.sensors[0], []).append((r, s))
    return {cond: {sensor: tuple(np.sqrt(np.mean(np.square(v), axis=0)))
                   for sensor, v in by.items()} for cond, by in acc.items()}
