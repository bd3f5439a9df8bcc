"""The sensor's converter in each sensor's value distribution: piles at a limit and the value
lattice, their statistics (with the dropouts' shares), and the evidence
``saturation_quantization`` is fitted to (limits, lattices, dropouts)."""
from __future__ import annotations

import functools
from typing import Any, Sequence

import numpy as np

from ..core.khepera import DARK
from ..effects.base import Array, Key, Row
from ..effects.fitting import Z_DETECT, on_grid
from ..recording import reading_range
from . import bootstrap
from .closedloop import sum_by
from .dropouts import dropouts, shares, share_keys

PILE_ENDS = ('at the lowest reading', 'at the highest reading')
MODULI = (2, 3, 4, 5, 8, 10)     # lattice steps the granularity statistics test
COARSEST = 32                    # the coarsest lattice step looked for
TAIL, WIDTH = 0.02, 1.0          # where a pile is looked for, and how wide it is
# a limit at v: the simulator puts EXPECTED readings beyond v, the real readings at v are
# HELD of those the simulator puts at or beyond, exceed its count at v by MIN_SHARE of the
# readings and Z Poisson sds, and exceed the next real value inward
EXPECTED, HELD, MIN_SHARE, Z = 5.0, 0.5, 0.002, 3.0
MIN_VALUES = 12                  # values inside its range a sensor needs in closed loop
BITS = 7                         # a block's count of a flag in a packed sum: below 128


# -- piles and the lattice -------------------------------------------------------------

def piles(x: Array) -> tuple[float | None, float | None]:
    """(low, high): the most common value among the outermost ``TAIL`` of ``x``."""
    x = x[np.isfinite(x)]
    if x.size == 0:
        return None, None
    values, counts = np.unique(x, return_counts=True)
    k = max(1, int(np.ceil(TAIL * x.size)))
    if not np.all(x == np.round(x)):          # not whole values: the outermost k readings
        if 2 * k >= x.size:
            return float(values[np.argmax(counts)]), float(values[::-1][np.argmax(counts[::-1])])
        part = np.partition(x, (k - 1, x.size - k))
        (lows, nl), (highs, nh) = (np.unique(p, return_counts=True)
                                   for p in (part[:k], part[x.size - k:]))
        return float(lows[np.argmax(nl)]), float(highs[::-1][np.argmax(nh[::-1])])
    return _piles_of(values, counts)          # whole values: those up to the tail's share


def edge_hits(x: Array) -> Array:
    """(N, C, 2): 1 where a sample lies within ``WIDTH`` of its channel's pile values."""
    out = np.zeros(x.shape + (2,))
    for k in range(x.shape[1]):
        for end, value in enumerate(piles(x[:, k])):
            if value is not None:
                out[:, k, end] = np.abs(x[:, k] - value) <= WIDTH
    return out


def stationary_sums(x: Array, marks: Array, cell: np.ndarray, order: np.ndarray,
                    total: Any) -> dict[str, Array]:
    """Sums by ``total``'s groups (of the samples ``order`` keeps) of the statistics."""
    o, c = order, x.shape[1]
    low, high = (x.min(), x.max()) if x.size else (np.nan, np.nan)
    if not (np.isfinite(low) and high - low < 1e5 and np.all(x == np.round(x))):
        return {'edge': total(edge_hits(x)[o]), 'dropped': _dropped(marks, order, total)}
    # whole readings: everything from histograms of values (cell by channel)
    xi = (x - low).astype(np.int64)
    span, cells = int(xi.max()) + 1, int(cell.max()) + 1
    channel = np.arange(c)[None, :]
    code = (cell[:, None] * c + channel) * span + xi                   # (cell, channel, value)
    size = cells * c * span
    per_cell = np.bincount(code.ravel(), minlength=size)
    rest = np.ones(len(x), bool)
    rest[o] = False              # the few samples no block keeps count for the cell's mode
    kept = per_cell - np.bincount(code[rest].ravel(), minlength=size) if rest.any() else per_cell
    per_cell, kept = per_cell.reshape(cells, c, span), kept.reshape(cells, c, span)
    hist = per_cell.sum(axis=0)                                        # (C, span)
    values = np.arange(span) + low
    flag = 2 + len(MODULI)
    table = np.zeros((span, c, flag), np.float32)                      # per value: ends, lattice
    for k in range(c):
        seen = hist[k] > 0
        for end, pile in enumerate(_piles_of(values[seen], hist[k][seen])):
            table[:, k, end] = np.abs(values - pile) <= WIDTH
    for j, q in enumerate(MODULI):
        residue = np.mod(values, q).astype(np.int64)
        modal = (hist @ (residue[:, None] == np.arange(q)[None, :])).argmax(axis=1)   # (C,)
        table[:, :, 2 + j] = residue[:, None] == modal[None, :]
    mode = per_cell.argmax(axis=2)                                     # (cells, C)
    if total.size == cells:       # whole cells: each one's histogram of the kept samples
        sums = np.stack([kept[:, k] @ table[:, k] for k in range(c)], axis=1)
        at_mode = np.take_along_axis(kept, mode[:, :, None], axis=2)[:, :, 0].astype(float)
    elif total.contiguous and total.count.max() < 1 << BITS:
        # counts: per (cell, channel, value) its flags and whether it is the cell's mode, as
        # bit fields of one integer added up per block (no field overflows)
        packed = (table.astype(np.int64) << (BITS * np.arange(flag))).sum(axis=2).T
        packed = np.repeat(packed[None], cells, axis=0)                # (cells, C, span)
        packed[np.arange(cells)[:, None], channel, mode] += 1 << (BITS * flag)
        by_block = np.zeros((total.size, c), np.int64)
        by_block[total.first_group] = np.add.reduceat(packed.ravel()[code[o]], total.first, axis=0)
        count = (by_block[..., None] >> (BITS * np.arange(flag + 1))) & ((1 << BITS) - 1)
        sums, at_mode = count[..., :flag].astype(np.float32), count[..., flag].astype(np.float32)
    else:
        xo = xi[o]
        flags = table.reshape(span * c, -1)[(xo * c + channel).ravel()].reshape(len(o), -1)
        sums = total(flags).reshape(-1, c, flag)
        at_mode = total((xo == mode[cell[o]]).astype(np.float32))
    return {'edge': sums[:, :, :2], 'dropped': _dropped(marks, order, total), 'at_mode': at_mode,
            'residue': sums[:, :, 2:]}


def _dropped(marks: Array, order: np.ndarray, total: Any) -> Array:
    """``total(marks[order])`` from the few marks there are (adding zeros adds nothing)."""
    width = marks[0].size if len(marks) else 0
    out = np.zeros((total.size, width), np.result_type(marks.dtype, np.float32))
    hit = np.flatnonzero(marks.ravel() != 0) if marks.any() else np.zeros(0, np.int64)
    place = np.full(len(marks), -1)
    place[order] = np.arange(order.size)
    at = place[hit // width]
    hit, at = hit[at >= 0], at[at >= 0]
    by = np.argsort(at, kind='stable')                # in the order ``total`` adds them
    np.add.at(out, (total.group[at[by]], hit[by] % width), marks.reshape(-1)[hit[by]])
    return out.reshape((total.size,) + marks.shape[1:])


def _piles_of(values: Array, counts: np.ndarray) -> tuple[float, float]:
    """``piles`` of whole readings given as distinct values and their counts."""
    cum = np.cumsum(counts)
    tail = max(1, int(np.searchsorted(cum, TAIL * cum[-1])) + 1)
    return (float(values[np.argmax(counts[:tail])]),
            float(values[values.size - 1 - np.argmax(counts[::-1][:tail])]))


def stationary_stats(b: bootstrap.Blocks, s: Array) -> tuple[list[Key], list[Array]]:
    n = b.part(s, 'n')[..., 0]
    total = n.sum(axis=1)[:, None]
    r, conditions = s.shape[0], tuple(dict.fromkeys(c for c, _ in b.strata))
    cols = [(b.part(s, 'edge').sum(axis=1) / total[..., None]).reshape(r, -1)]
    cols += shares(b.channels, b.part(s, 'dropped').sum(axis=1) / total[..., None])
    if b.has('at_mode'):
        for cond in conditions:
            m = [i for i, lab in enumerate(b.strata) if lab[0] == cond]
            cols.append(b.part(s, 'at_mode')[:, m].sum(axis=1) / n[:, m].sum(axis=1)[:, None])
        cols.append((b.part(s, 'residue').sum(axis=1) / total[..., None]).reshape(r, -1))
    return _stationary_keys(b.channels, conditions, b.has('at_mode')), cols


@functools.lru_cache(maxsize=64)
def _stationary_keys(ch: tuple[int, ...], conditions: tuple[str, ...], lattice: bool) -> list[Key]:
    out = [Key('pileup', (k,), None, end) for k in ch for end in PILE_ENDS]
    out += share_keys('dropout', ch, None)
    if lattice:
        out += [Key('mode_share', (k,), cond, None) for cond in conditions for k in ch]
        out += [Key('granularity', (k,), None, f'step {q}') for k in ch for q in MODULI]
    return out


def loop_sums(x: Array, marks: Array, ep: np.ndarray, episodes: int,
              values: bool) -> dict[str, Array]:
    """Per-episode sums; ``values``: the lattice too (no stationary recording beside)."""
    by = functools.partial(sum_by, ep, episodes=episodes)
    out = {'dropped': by(marks[:, :8])}
    r = x[:, :8]
    if values and np.isfinite(r).all() and np.all(r == np.round(r)):
        weight, on = _on_lattice(r)
        out['lv_weight'], out['lv_residue'] = by(weight), by(on * weight[..., None])
    return out


def _on_lattice(r: Array) -> tuple[Array, Array]:
    """((N, C) weights that count each value seen once, none at the extremes; (N, C, Q) on
    the sensor's most common residue)."""
    weight, on = np.zeros(r.shape), np.zeros(r.shape + (len(MODULI),))
    for k in range(r.shape[1]):
        values, index, counts = np.unique(r[:, k], return_inverse=True, return_counts=True)
        inner = (values > r[:, k].min()) & (values < r[:, k].max())
        weight[:, k] = np.where(inner, 1.0 / counts, 0.0)[index.ravel()]
        for j, q in enumerate(MODULI):
            residue = np.mod(values, q).astype(np.int64)
            modal = np.bincount(residue[inner], minlength=q).argmax()
            on[:, k, j] = (residue == modal)[index.ravel()]
    return weight, on


def loop_stats(b: bootstrap.Blocks, s: Array, i: int,
               condition: str) -> tuple[list[Key], list[Array]]:
    """Stratum ``i``'s (one condition's) closed-loop converter statistics."""
    n = b.part(s, 'n')[:, i, 0]
    keys = list(share_keys('closed_loop_dropout', tuple(range(8)), condition))
    cols = shares(range(8), b.part(s, 'dropped')[:, i] / n[:, None, None])
    if b.has('lv_weight'):
        weight = b.part(s, 'lv_weight')[:, i]
        share = b.part(s, 'lv_residue')[:, i] / weight[..., None]
        for k in range(8):
            if weight[0, k] >= MIN_VALUES:
                keys += [Key('loop_granularity', (k,), condition, f'step {q}') for q in MODULI]
                cols.append(share[:, k])
    return keys, cols


# -- evidence for the converter's fit ------------------------------------------------------

def evidence(real: Sequence[Any], sim: Sequence[Any], grains: list[Row]) -> dict[str, Any]:
    """The value distributions of repaired recordings ``real`` against their replays
    ``sim``: the limits, each sensor's lattice where the simulator's readings are off it
    (``grains``: the granularity statistics, flagged beyond ``Z_DETECT``), dropouts."""
    rec = real[0].recording
    real_x = np.concatenate([r.recording.readings for r in real])
    sim_x = np.concatenate([r.recording.readings for r in sim])
    bounds = reading_range(rec.manifest, rec.channels)
    timed = {r.key.sensors[0] for r in grains}
    flagged = {r.key.sensors[0] for r in grains if r.z > Z_DETECT}
    inner = {s: _inner(real_x[:, s]) for s in rec.channels_used}
    pooled = grid(np.concatenate(list(inner.values())))
    lattices = {}
    for sensor in rec.channels_used:
        x = real_x[:, sensor]
        lattice = grid(inner[sensor])
        if lattice[0] == 1 and inner[sensor].size < 20 and pooled[0] > 1 and \
                on_grid(x[np.isfinite(x)], *pooled) >= 0.95:
            lattice = pooled      # too few values of its own: the other sensors' lattice
        # without granularity statistics: the simulator's readings off the real lattice
        shown = sensor in flagged if sensor in timed else grid(_inner(sim_x[:, sensor])) != lattice
        if lattice[0] > 1 and shown:
            lattices[sensor] = lattice
    lost = dropouts(real, sim)
    top = max(DARK, *(v for v in bounds if np.isfinite(v)), *(v for v, _ in lost.values()))
    return {'limits': limits(real_x, sim_x, rec.channels_used, bounds), 'lattices': lattices,
            'dropouts': lost, 'top': top}


def _inner(x: Array) -> Array:
    """The finite readings strictly between their least and greatest."""
    x = x[np.isfinite(x)]
    return x[(x > x.min()) & (x < x.max())] if x.size else x


def limits(real: Array, sim: Array, sensors: Sequence[int],
           reading_range: tuple[float, float]) -> list[dict[str, Any]]:
    """The limits the real readings pile up at where the simulator passes them: {end,
    value, share, sensors}, pooled over the sensors with that extreme."""
    out: list[dict[float, list[tuple[Any, ...]]]] = [{}, {}]
    for sensor in sensors:
        x, y = real[:, sensor], sim[:, sensor]
        x, y = x[np.isfinite(x)], y[np.isfinite(y)]
        values, count = np.unique(x, return_counts=True)
        if values.size == 0 or y.size == 0:
            continue
        ends: list[tuple[Any, ...] | None] = [(values[0], count[0], 0)] * 2
        if values.size > 1:
            ends = [(values[0], count[0], count[1]), (values[-1], count[-1], count[-2])]
        else:       # held at one value: the limit on the side the simulator passes
            ends[int(np.mean(y > values[0]) < np.mean(y < values[0]))] = None
        for end, found_ in enumerate(ends):
            if found_ is None or found_[0] == reading_range[end]:
                continue
            value, at, inner = found_
            beyond, held = (np.mean(y < value), np.mean(y <= value)) if end == 0 else \
                (np.mean(y > value), np.mean(y >= value))
            out[end].setdefault(float(value), []).append(
                (sensor, at, inner, x.size, beyond, held, np.mean(y == value)))
    found = []
    for end, by_value in enumerate(out):
        for value, rows in by_value.items():
            at, inner, n = (sum(r[j] for r in rows) for j in (1, 2, 3))
            expected, held, there = (sum(r[3] * r[j] for r in rows) for j in (4, 5, 6))
            if expected >= EXPECTED and at >= HELD * held and at > inner \
                    and at - there >= MIN_SHARE * n and at - there > Z * np.sqrt(there + 1.0):
                found.append({'end': end, 'value': value, 'share': round(float(at / n), 5),
                              'sensors': tuple(sorted(r[0] for r in rows))})
    return found


def grid(x: Array) -> tuple[float, float]:
    """(step, origin): the coarsest lattice holding nearly all of ``x``: for whole readings
    a step of 2..32, exactly; for others (readings converted from another unit) the step
    their distinct values keep, to a tenth of a step, if it lies above 1 and up to 32."""
    if x.size < 20:
        return 1, 0
    values, weight = np.unique(x, return_counts=True)
    if not np.all(x == np.round(x)):
        return _measured(values, weight)
    for q in range(COARSEST, 1, -1):
        hist = np.bincount(np.mod(values, q).astype(np.int64), weights=weight)
        if hist.max() >= 0.95 * x.size:
            return q, int(hist.argmax())
    return 1, 0


def _measured(values: Array, weight: np.ndarray) -> tuple[float, float]:
    """``grid`` of readings that are not whole: the typical gap between distinct values,
    averaged over the gaps it divides, and the origin the values sit around."""
    gaps = np.diff(values)
    step = float(gaps.sum() / np.round(gaps / np.median(gaps)).sum()) if gaps.size > 1 else 0.0
    if not 1.0 < step <= COARSEST:
        return 1, 0
    turn = np.exp(2j * np.pi * (values - values[0]) / step) @ weight
    origin = values[0] + np.angle(turn) / (2 * np.pi) * step
    step, origin = round(step, 4), round(float(origin - step * np.round(origin / step)), 4) + 0.0
    if on_grid(values, step, origin, weight) < 0.95:
        return 1, 0
    return step, origin
