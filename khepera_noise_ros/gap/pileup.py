"""Limits from the pile-up of readings at one value.

A floor or a ceiling inside the reading range (a converter that saturates just
inside the range the light reaches) shows as a spike in a sensor's histogram at
the edge of its distribution, with nothing beyond it, even when it touches only a
few percent of the readings.  Three things together say so: the simulator, which
has no limit there, puts readings beyond the value where the real sensor has none
(a chance of about exp(-expected count)); the real readings pile up at the value
beyond the simulator's count there, by about as many as it puts beyond (merely
narrower noise has no pile); and the pile stands above the next real value inward
(a lattice has no step at its end).  Sensors whose extremes sit at the same value
are pooled, so a limit shared by all sensors is found even when each touches few
readings.  ``edge_hits`` gives the statistic the comparison sees.
"""
from __future__ import annotations

import numpy as np

ENDS = ('at the lowest reading', 'at the highest reading')
TAIL = 0.02         # the pile statistic looks for a pile in this share of readings at each end
WIDTH = 1.0         # and counts the readings this close to it
# A limit at value v (see the module's docstring): the simulator puts EXPECTED readings
# beyond v (none are real: a chance of exp(-5) without a limit); the real readings at v
# are HELD of those the simulator puts at or beyond v, exceed its count at v by MIN_SHARE
# of the readings and Z Poisson sds, and exceed the next real value inward.
EXPECTED = 5.0
HELD = 0.5
MIN_SHARE = 0.002
Z = 3.0


def edge_hits(x: np.ndarray) -> np.ndarray:
    """(N, C, 2) float32: 1 where a sample lies within ``WIDTH`` of its channel's low (high)
    pile value, the most common reading among the outermost ``TAIL`` of them.  Summed and
    divided by N: the share held at each end, the share a limit clips (plus a little),
    a few times ``TAIL`` / (values in the tail) for a smooth tail.  The mode and the
    window keep it steady when a slow change moves a pile or strays lie beyond it."""
    out = np.zeros(x.shape + (2,), np.float32)
    for k in range(x.shape[1]):
        col = x[:, k]
        for end, value in enumerate(_piles(col[np.isfinite(col)])):
            if value is not None:
                out[:, k, end] = np.abs(col - value) <= WIDTH
    return out


def _piles(x: np.ndarray) -> tuple:
    """(low, high) the most common value among the outermost ``TAIL`` of ``x`` at each end
    (the outermost of equals): by counting when the readings are small integers, else
    from the tails alone (a partition, not a sort)."""
    if x.size == 0:
        return None, None
    if np.all(x == np.round(x)) and np.ptp(x) < 1e5:
        low = x.min()
        counts = np.bincount((x - low).astype(np.int64))
        values = np.flatnonzero(counts)
        counts = counts[values]
        cum = np.cumsum(counts)
        tail = max(1, int(np.searchsorted(cum, TAIL * cum[-1])) + 1)
        return (float(values[np.argmax(counts[:tail])] + low),
                float(values[values.size - 1 - np.argmax(counts[::-1][:tail])] + low))
    k = max(1, int(np.ceil(TAIL * x.size)))
    if 2 * k >= x.size:
        values, counts = np.unique(x, return_counts=True)
        return float(values[np.argmax(counts)]), float(values[::-1][np.argmax(counts[::-1])])
    part = np.partition(x, (k - 1, x.size - k))
    lows, low_counts = np.unique(part[:k], return_counts=True)
    highs, high_counts = np.unique(part[x.size - k:], return_counts=True)
    return (float(lows[np.argmax(low_counts)]),
            float(highs[::-1][np.argmax(high_counts[::-1])]))


def _ends(x: np.ndarray) -> list:
    """Per end: (value, count at it, count at the next value inward) of finite ``x``."""
    values, counts = np.unique(x[np.isfinite(x)], return_counts=True)
    if values.size < 2:
        return [None, None]
    return [(float(values[0]), int(counts[0]), int(counts[1])),
            (float(values[-1]), int(counts[-1]), int(counts[-2]))]


def limits(real: np.ndarray, sim: np.ndarray, sensors, reading_range) -> list[dict]:
    """The limits the real readings pile up at, per end: a list of {sensors, value, share}
    (share: mean share of the located sensors' readings held there), pooled over the
    sensors whose extreme sits at the same value; limits of the reading range itself
    are modelled and do not count.  ``real``, ``sim``: (samples, channels) readings."""
    out = [{}, {}]
    for sensor in sensors:
        x, y = real[:, sensor], sim[:, sensor]
        y = y[np.isfinite(y)]
        n = np.isfinite(x).sum()
        for end, found in enumerate(_ends(x)):
            if found is None or found[0] == reading_range[end] or y.size == 0:
                continue
            value, at, inner = found
            beyond, held = (np.mean(y < value), np.mean(y <= value)) if end == 0 else \
                (np.mean(y > value), np.mean(y >= value))
            out[end].setdefault(value, []).append((sensor, at, inner, n, beyond, held,
                                                   np.mean(y == value)))
    found = []
    for end, by_value in enumerate(out):
        for value, rows in by_value.items():
            at = sum(r[1] for r in rows)
            inner = sum(r[2] for r in rows)
            n = sum(r[3] for r in rows)
            expected = sum(r[3] * r[4] for r in rows)   # readings the simulator puts beyond
            held = sum(r[3] * r[5] for r in rows)       # ... at or beyond
            there = sum(r[3] * r[6] for r in rows)      # ... at the value
            if expected >= EXPECTED and at >= HELD * held and at > inner \
                    and at - there >= MIN_SHARE * n and at - there > Z * np.sqrt(there + 1.0):
                found.append({'end': end, 'value': value, 'share': round(float(at / n), 5),
                              'sensors': tuple(sorted(r[0] for r in rows))})
    return found


def strongest(found: list, end: int) -> dict | None:
    """The limit at ``end`` (0 floor, 1 ceiling) holding the most readings."""
    mine = [f for f in found if f['end'] == end]
    return max(mine, key=lambda f: f['share'] * len(f['sensors'])) if mine else None
