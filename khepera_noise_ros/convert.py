"""Public multi-sensor logs to the recording format (khepera-noise-recording/1).

Two published layouts are read: the Room Occupancy Estimation CSV (UCI; four
sensor nodes with light and temperature sampled together, labelled with the
number of people in the room) and the Intel Berkeley Research Lab log (54
motes, one line per mote and epoch).  Up to eight chosen channels become
s0..s7.  Each quantity gets one affine map onto 0..525 shared by its channels,
with 0 for the most of the quantity (brightest, warmest), so differences
between sensors survive.  Conditions come from the data's own labels (people
in the room) or its clock (day, night).  A run of samples becomes episodes of
at most ``episode_length`` samples, split wherever the label changes, the
clock jumps, the day changes or a value is missing, so no step is lost.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

import numpy as np

from .recording import FORMAT, KHEPERA_CHANNELS, Recording

DARK = 525.0
FORMATS = ('room-occupancy', 'intel-lab')
OCCUPANCY_CHANNELS = ('S1_Light', 'S2_Light', 'S3_Light', 'S4_Light',
                      'S1_Temp', 'S2_Temp', 'S3_Temp', 'S4_Temp')
OCCUPANCY_PERIOD_S = 30.0        # the dataset's documented sampling interval
INTEL_QUANTITIES = ('temperature', 'humidity', 'light', 'voltage')
INTEL_PERIOD_S = 31.0            # one epoch: a reading from every mote every 31 s
DAY_HOURS = (7, 19)              # intel-lab conditions: day from 07:00 to 19:00


@dataclass
class Table:
    """Samples in time order before they become a recording."""

    time_s: np.ndarray           # (N,) seconds, NaN where the log has no clock
    day: np.ndarray              # (N,) str, '' without a clock
    label: np.ndarray            # (N,) str condition labels
    values: np.ndarray           # (N, C) float, NaN where missing
    channels: list[dict]         # per channel: column, quantity, unit


# -- readers ------------------------------------------------------------------------------

def _quantity(column: str) -> tuple[str, str]:
    low = column.lower()
    if 'light' in low:
        return 'light', 'lux'
    if 'temp' in low:
        return 'temperature', 'degC'
    if 'sound' in low:
        return 'sound', 'V'
    if 'co2' in low:
        return 'co2', 'ppm'
    return low, ''


def _parse_when(date: str, time: str, where: str) -> datetime:
    for fmt in ('%Y/%m/%d', '%Y-%m-%d', '%d-%m-%Y', '%d/%m/%Y'):
        try:
            day = datetime.strptime(date.strip(), fmt)
            break
        except ValueError:
            continue
    else:
        raise ValueError(f'{where}: date {date!r} is not YYYY/MM/DD, YYYY-MM-DD or DD-MM-YYYY')
    try:
        clock = datetime.strptime(time.strip().split('.')[0], '%H:%M:%S')
    except ValueError:
        raise ValueError(f'{where}: time {time!r} is not HH:MM:SS') from None
    return day.replace(hour=clock.hour, minute=clock.minute, second=clock.second)


def _number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        return math.nan
    return value if math.isfinite(value) else math.nan


def read_room_occupancy(path, channels=OCCUPANCY_CHANNELS) -> Table:
    """The UCI Room Occupancy Estimation CSV (with or without its Date and Time columns)."""
    path = Path(path)
    with open(path, newline='') as f:
        reader = csv.DictReader(f)
        header = reader.fieldnames or []
        missing = [c for c in list(channels) + ['Room_Occupancy_Count'] if c not in header]
        if missing:
            raise ValueError(f'{path}: no column(s) {missing}; the file has {header}')
        clocked = 'Date' in header and 'Time' in header
        times, days, labels, rows = [], [], [], []
        for row in reader:
            where = f'{path} line {reader.line_num}'
            count = row['Room_Occupancy_Count'].strip()
            if not count.isdigit():
                raise ValueError(f'{where}: Room_Occupancy_Count must be a count, got {count!r}')
            labels.append(f'occupancy_{int(count)}')
            rows.append([_number(row[c]) for c in channels])
            if clocked:
                when = _parse_when(row['Date'], row['Time'], where)
                times.append(when.timestamp())
                days.append(when.date().isoformat())
    if not rows:
        raise ValueError(f'{path}: no samples')
    n = len(rows)
    return Table(np.asarray(times, float) if clocked else np.full(n, np.nan),
                 np.asarray(days if clocked else [''] * n), np.asarray(labels),
                 np.asarray(rows, float),
                 [dict(zip(('quantity', 'unit'), _quantity(c)), column=c) for c in channels])


def read_intel_lab(path, motes, quantity: str = 'light') -> Table:
    """The Intel Lab log: ``date time epoch moteid temperature humidity light voltage``.

    A sample is an epoch at which every chosen mote reported; lines with fields
    missing (the log has some) are skipped.
    """
    path = Path(path)
    if quantity not in INTEL_QUANTITIES:
        raise ValueError(f'quantity must be one of {INTEL_QUANTITIES}, got {quantity!r}')
    motes = [int(m) for m in motes]
    column = 4 + INTEL_QUANTITIES.index(quantity)
    wanted = {m: i for i, m in enumerate(motes)}
    by_epoch: dict[int, dict] = {}
    with open(path) as f:
        for number, line in enumerate(f, 1):
            parts = line.split()
            if len(parts) != 8:
                continue
            try:
                mote, epoch = int(parts[3]), int(parts[2])
            except ValueError:
                raise ValueError(f'{path} line {number}: epoch and moteid must be integers, '
                                 f'got {parts[2]!r}, {parts[3]!r}') from None
            if mote not in wanted:
                continue
            entry = by_epoch.setdefault(epoch, {'values': [math.nan] * len(motes)})
            entry['values'][wanted[mote]] = _number(parts[column])
            when = _parse_when(parts[0], parts[1], f'{path} line {number}')
            entry['when'] = min(entry.get('when', when), when)
    epochs = sorted(e for e, v in by_epoch.items() if not any(map(math.isnan, v['values'])))
    if not epochs:
        raise ValueError(f'{path}: no epoch at which all of motes {motes} reported {quantity}')
    whens = [by_epoch[e]['when'] for e in epochs]
    labels = ['day' if DAY_HOURS[0] <= w.hour < DAY_HOURS[1] else 'night' for w in whens]
    unit = {'temperature': 'degC', 'humidity': '%', 'light': 'lux', 'voltage': 'V'}[quantity]
    return Table(np.asarray([w.timestamp() for w in whens]),
                 np.asarray([w.date().isoformat() for w in whens]), np.asarray(labels),
                 np.asarray([by_epoch[e]['values'] for e in epochs], float),
                 [{'column': f'mote{m}_{quantity}', 'quantity': quantity, 'unit': unit}
                  for m in motes])


# -- to a recording -----------------------------------------------------------------------

def scales(table: Table, ranges: dict | None = None) -> dict[str, tuple[float, float]]:
    """(low, high) per quantity: given, else the data's own range over its channels."""
    ranges = dict(ranges or {})
    out = {}
    for q in dict.fromkeys(c['quantity'] for c in table.channels):
        cols = [i for i, c in enumerate(table.channels) if c['quantity'] == q]
        if q in ranges:
            low, high = ranges[q]
        else:
            v = table.values[:, cols]
            v = v[np.isfinite(v)]
            if v.size == 0:
                raise ValueError(f'no {q} values to scale')
            low, high = float(v.min()), float(v.max())
        if not high > low:
            high = low + 1.0
        out[q] = (float(low), float(high))
    return out


def to_readings(table: Table, ranges: dict) -> np.ndarray:
    """0..525, 0 at the most of each quantity."""
    low = np.array([ranges[c['quantity']][0] for c in table.channels])
    high = np.array([ranges[c['quantity']][1] for c in table.channels])
    return np.clip(DARK * (high - table.values) / (high - low), 0.0, DARK)


def episodes(table: Table, period_s: float, episode_length: int, min_length: int) -> np.ndarray:
    """Episode index per sample, -1 for samples dropped (missing values, short runs)."""
    n = len(table.label)
    ok = np.isfinite(table.values).all(axis=1)
    gap = np.zeros(n, bool)
    if np.isfinite(table.time_s).all() and n > 1:
        gap[1:] = np.diff(table.time_s) > 1.5 * period_s
    start = np.ones(n, bool)
    start[1:] = (table.label[1:] != table.label[:-1]) | (table.day[1:] != table.day[:-1]) \
        | gap[1:] | ~ok[:-1]
    out = np.full(n, -1)
    run, length, members = -1, 0, []
    finished = []
    for i in range(n):
        if not ok[i]:
            continue
        if start[i] or length >= episode_length:
            finished.append(members)
            members, length = [], 0
        members.append(i)
        length += 1
    finished.append(members)
    for members in finished:
        if len(members) >= min_length:
            run += 1
            out[members] = run
    return out


def period_of(table: Table, default: float) -> float:
    if np.isfinite(table.time_s).all() and len(table.time_s) > 1:
        steps = np.diff(table.time_s)
        steps = steps[steps > 0]
        if steps.size:
            return float(np.median(steps))
    return default


def to_recording(table: Table, source_name: str, fmt: str, period_s: float,
                 episode_length: int = 60, min_length: int = 10,
                 ranges: dict | None = None) -> Recording:
    """The recording of ``table``: stationary, no headings, source hardware."""
    if not 1 <= len(table.channels) <= KHEPERA_CHANNELS:
        raise ValueError(f'choose 1..{KHEPERA_CHANNELS} channels, got {len(table.channels)}')
    if episode_length < 2 or not 1 <= min_length <= episode_length:
        raise ValueError(f'need episode_length >= 2 and 1 <= min_length <= episode_length, '
                         f'got {episode_length} and {min_length}')
    rng = scales(table, ranges)
    episode = episodes(table, period_s, episode_length, min_length)
    keep = episode >= 0
    if not keep.any():
        every = episodes(table, period_s, episode_length, 1)
        longest = int(np.bincount(every[every >= 0]).max()) if (every >= 0).any() else 0
        raise ValueError(f'no run of {min_length} complete samples in {source_name} (the '
                         f'longest is {longest}: fewer channels or a lower --min-length '
                         f'keep more)')
    readings = np.full((len(table.label), KHEPERA_CHANNELS), DARK)
    readings[:, :len(table.channels)] = to_readings(table, rng)
    readings = readings[keep]
    episode = episode[keep]
    step = np.zeros(episode.size, int)
    for e in np.unique(episode):
        m = episode == e
        step[m] = np.arange(m.sum())
    labels = table.label[keep]
    n = int(keep.sum())
    used = list(range(len(table.channels)))
    manifest = {
        'format': FORMAT, 'source': 'hardware', 'sample_period_s': period_s,
        'protocol': 'stationary',
        'conditions': {str(c): {} for c in dict.fromkeys(labels.tolist())},
        'converted_from': {
            'format': fmt, 'file': source_name,
            'dropped_samples': int((~keep).sum()),
            'channels': {f's{i}': {**c, 'reading': '525 * (high - value) / (high - low)',
                                   'low': rng[c['quantity']][0],
                                   'high': rng[c['quantity']][1]}
                         for i, c in enumerate(table.channels)}}}
    if len(used) < KHEPERA_CHANNELS:
        manifest['channels_used'] = used
    first = table.time_s[keep]
    if np.isfinite(first).all():
        manifest['converted_from']['first_sample'] = datetime.fromtimestamp(
            float(first[0])).isoformat()
    return Recording(episode=episode.astype(np.int64), step=step.astype(np.int64),
                     heading_deg=np.full(n, np.nan), condition=labels.astype(str),
                     readings=readings, direction=np.full(n, np.nan),
                     power=np.full(n, np.nan), manifest=manifest)


def convert(fmt: str, path, channels=None, motes=None, quantity: str = 'light',
            episode_length: int = 60, min_length: int = 10,
            ranges: dict | None = None) -> Recording:
    """Read ``path`` in public layout ``fmt`` and return the recording."""
    if fmt == 'room-occupancy':
        table = read_room_occupancy(path, tuple(channels or OCCUPANCY_CHANNELS))
        period = period_of(table, OCCUPANCY_PERIOD_S)
    elif fmt == 'intel-lab':
        table = read_intel_lab(path, motes or range(1, 9), quantity)
        period = INTEL_PERIOD_S
    else:
        raise ValueError(f'format must be one of {FORMATS}, got {fmt!r}')
    if len(table.channels) > KHEPERA_CHANNELS:
        raise ValueError(f'choose at most {KHEPERA_CHANNELS} channels, got '
                         f'{len(table.channels)}')
    return to_recording(table, Path(path).name, fmt, period, episode_length, min_length, ranges)
