"""Limits from the pile-up of readings at one value.

A floor or a ceiling inside the reading range (a converter that saturates just
inside the range the light reaches) shows as a spike in a sensor's histogram at
the edge of its distribution, with nothing beyond it, even when it touches only a
few percent of the readings.  Two things together say so: the simulator, which has
no limit there, puts readings beyond that value where the real sensor has none
(a chance of about exp(-expected count)), and the real readings pile up at the
value, above the count at the next value present inward, by about as many as the
simulator puts beyond (merely narrower noise has no pile-up; a lattice or a
smooth tail has no step at its end).  Sensors whose extremes sit at the same value are pooled, so a
limit shared by all sensors is found even when each touches few readings.
"""
from __future__ import annotations

import numpy as np

ENDS = ('at the lowest reading', 'at the highest reading')
EDGE = 0.002        # the pile statistic's end: the outermost value this share of readings hold
MIN_SHARE = 0.002   # the pile must exceed the next value inward by this share of the readings
Z = 1.0             # and by this many Poisson sds;
EXPECTED = 5.0      # the simulator puts this many readings beyond the value (none are real:
#                   a chance of exp(-5) without a limit there;
HELD = 0.5          # the real pile holds this share of what the simulator puts at or beyond


def edge_hits(x: np.ndarray) -> np.ndarray:
    """(N, C, 2) float32: 1 where a sample is at its channel's lowest (highest) value held by
    at least ``EDGE`` of the readings.  Summed and divided by N, the share held at each
    end: a limit holds the share it clips, a smooth tail about ``EDGE``; a few stray
    readings beyond a pile do not move it."""
    out = np.zeros(x.shape + (2,), np.float32)
    for k in range(x.shape[1]):
        col = x[:, k]
        values, counts = _histogram(col[np.isfinite(col)])
        held = values[counts >= max(2.0, EDGE * counts.sum())]
        if held.size:
            out[:, k, 0] = col == held[0]
            out[:, k, 1] = col == held[-1]
    return out


def _histogram(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(values, counts) of ``x``; by counting when the readings are small integers."""
    if x.size and np.all(x == np.round(x)) and np.ptp(x) < 1e5:
        low = x.min()
        counts = np.bincount((x - low).astype(np.int64))
        present = np.flatnonzero(counts)
        return present + low, counts[present]
    return np.unique(x, return_counts=True)


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
            out[end].setdefault(value, []).append((sensor, at, inner, n, beyond, held))
    found = []
    for end, by_value in enumerate(out):
        for value, rows in by_value.items():
            at = sum(r[1] for r in rows)
            inner = sum(r[2] for r in rows)
            n = sum(r[3] for r in rows)
            share = (at - inner) / n
            expected = sum(r[3] * r[4] for r in rows)   # readings the simulator puts beyond
            held = sum(r[3] * r[5] for r in rows)       # ... at or beyond
            if expected >= EXPECTED and at >= HELD * held and share >= MIN_SHARE \
                    and at - inner > Z * np.sqrt(at + inner):
                found.append({'end': end, 'value': value, 'share': round(at / n, 5),
                              'sensors': tuple(sorted(r[0] for r in rows))})
    return found


def strongest(found: list, end: int) -> dict | None:
    """The limit at ``end`` (0 floor, 1 ceiling) holding the most readings."""
    mine = [f for f in found if f['end'] == end]
    return max(mine, key=lambda f: f['share'] * len(f['sensors'])) if mine else None
