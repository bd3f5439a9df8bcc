"""Recordings in the public format (DESIGN.md): CSV plus YAML manifest, and rosbag2 (MCAP).

The in-memory form is ``Recording``: one row per sample.  A Khepera file has
exactly the version-1 columns; a board with C != 8 light channels extends
them with s8, s9, ... and says so in the manifest (``channels``), which also
marks the channels that carry data (``channels_used``).  Readers are strict:
every problem is reported with the file, the line and what is wrong, because a
silently mangled recording would poison the synchrony and gap analyses.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from .files import atomic_open, atomic_write_text

FORMAT = 'khepera-noise-recording/1'
KHEPERA_CHANNELS = 8
COLUMNS = ('episode', 'step', 'heading_deg', 'condition') + tuple(f's{i}' for i in range(8)) \
    + ('direction', 'power')
SOURCES = ('simulator', 'emulator', 'hardware')
PROTOCOLS = ('stationary', 'closed_loop')
KHEPERA_RANGE = (0.0, 525.0)


class RecordingError(ValueError):
    """A recording that breaks the format; the message names the file, line and problem."""


def columns(channels: int = KHEPERA_CHANNELS) -> tuple[str, ...]:
    """CSV header for ``channels`` light channels (the v1 layout for 8)."""
    return COLUMNS[:4] + tuple(f's{i}' for i in range(channels)) + COLUMNS[-2:]


@dataclass
class Recording:
    """Samples of C light channels (8 for a Khepera); NaN where a value is not known."""

    episode: np.ndarray        # (N,) int
    step: np.ndarray           # (N,) int
    heading_deg: np.ndarray    # (N,) float, NaN where unknown (closed loop on hardware)
    condition: np.ndarray      # (N,) str, keys of manifest['conditions']
    readings: np.ndarray       # (N, C) float, 0 brightest .. 525 darkest on a Khepera
    direction: np.ndarray      # (N,) float, -1 left / +1 right, NaN in stationary data
    power: np.ndarray          # (N,) float, 0..9, NaN in stationary data
    manifest: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.episode.size)

    @property
    def channels(self) -> int:
        return int(self.readings.shape[1])

    @property
    def channels_used(self) -> list[int]:
        """Channels that carry data: the manifest's ``channels_used``, else all."""
        return list(self.manifest.get('channels_used', range(self.channels)))

    def select(self, mask: np.ndarray) -> 'Recording':
        """The rows where ``mask`` is true, with the same manifest."""
        return Recording(self.episode[mask], self.step[mask], self.heading_deg[mask],
                         self.condition[mask], self.readings[mask], self.direction[mask],
                         self.power[mask], self.manifest)

    def conditions(self) -> list[str]:
        """Condition labels in order of first appearance."""
        labels, first = np.unique(self.condition, return_index=True)
        return [str(labels[i]) for i in np.argsort(first)]

    def step_problems(self) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
        """(lost, duplicated) (episode, step) pairs: each step should appear exactly once.

        A step is lost when it is missing between 0 and the last step seen in its episode.
        """
        keys = self.episode.astype(np.int64) * (1 << 32) + self.step.astype(np.int64)
        unique, counts = np.unique(keys, return_counts=True)
        duplicated = [_split(k) for k in unique[counts > 1]]
        lost = []
        for e in np.unique(self.episode):
            seen = set(self.step[self.episode == e].tolist())
            lost += [(int(e), s) for s in range(max(seen) + 1) if s not in seen]
        return lost, duplicated

    def check(self) -> None:
        """Shapes, values and manifest, or a RecordingError naming the problem."""
        n = len(self)
        if self.readings.ndim != 2 or self.readings.shape[0] != n or self.channels < 1:
            raise RecordingError(f'readings must be ({n}, channels), got {self.readings.shape}')
        for name in ('step', 'heading_deg', 'condition', 'direction', 'power'):
            if getattr(self, name).shape != (n,):
                raise RecordingError(f'{name} must have shape ({n},), got '
                                     f'{getattr(self, name).shape}')
        try:
            check_manifest(self.manifest, self.channels, in_file=False)
        except ValueError as exc:
            raise RecordingError(f'manifest: {exc}') from None
        bad = first_bad_row(self)
        if bad:
            raise RecordingError(f'sample {bad[0]}: {bad[1]}')


def from_trace(trace, condition: str, manifest: dict, first_episode: int = 0,
               stationary: bool = False) -> Recording:
    """Rows from a core ``Trace`` (arrays (steps, B, ...)): robot b is episode first + b.

    ``stationary`` leaves direction and power empty, as the format asks of
    recordings in which the robot did not act.
    """
    steps, robots = trace.power.shape
    by_robot = (lambda a: np.swapaxes(np.asarray(a, np.float64), 0, 1)
                .reshape(robots * steps, *np.shape(a)[2:]))
    empty = np.full(robots * steps, np.nan)
    return Recording(
        episode=np.repeat(np.arange(robots) + first_episode, steps),
        step=np.tile(np.arange(steps), robots), heading_deg=by_robot(trace.bearing_deg),
        condition=np.full(robots * steps, condition), readings=by_robot(trace.readings),
        direction=empty if stationary else by_robot(trace.direction),
        power=empty if stationary else by_robot(trace.power), manifest=manifest)


def concatenate(recordings: list[Recording], manifest: dict | None = None) -> Recording:
    """One recording from several, in order; the manifest's conditions are merged."""
    if not recordings:
        raise ValueError('nothing to concatenate')
    if manifest is None:
        manifest = dict(recordings[0].manifest)
        manifest['conditions'] = {k: v for r in recordings
                                  for k, v in r.manifest.get('conditions', {}).items()}
    join = (lambda name: np.concatenate([getattr(r, name) for r in recordings]))
    return Recording(join('episode'), join('step'), join('heading_deg'), join('condition'),
                     join('readings'), join('direction'), join('power'), manifest)


def _split(key: int) -> tuple[int, int]:
    return int(key) >> 32, int(key) & 0xFFFFFFFF


# -- manifest -----------------------------------------------------------------------------

def check_manifest(manifest: dict, channels: int, in_file: bool = True) -> None:
    """Raise ValueError naming the first manifest key that breaks the format.

    In a file, any channel count but 8 must be declared; in memory the data says it.
    """
    if not isinstance(manifest, dict):
        raise ValueError(f'the manifest must be a mapping, got {type(manifest).__name__}')
    if manifest.get('format') != FORMAT:
        raise ValueError(f'format must be {FORMAT!r}, got {manifest.get("format")!r}')
    if manifest.get('source') not in SOURCES:
        raise ValueError(f'source must be one of {SOURCES}, got {manifest.get("source")!r}')
    period = manifest.get('sample_period_s')
    if not _is_number(period) or not period > 0:
        raise ValueError(f'sample_period_s must be a positive number, got {period!r}')
    conditions = manifest.get('conditions')
    if not isinstance(conditions, dict) or not conditions \
            or not all(isinstance(k, str) and k for k in conditions):
        raise ValueError(f'conditions must map non-empty labels to world parameters, '
                         f'got {conditions!r}')
    if 'protocol' in manifest and manifest['protocol'] not in PROTOCOLS:
        raise ValueError(f'protocol must be one of {PROTOCOLS}, got {manifest["protocol"]!r}')
    declared = manifest.get('channels', KHEPERA_CHANNELS if in_file else channels)
    if declared != channels:
        raise ValueError(f'channels is {declared!r} but the data has {channels} channels')
    used = manifest.get('channels_used', list(range(channels)))
    if not isinstance(used, list) or not used or len(set(used)) != len(used) \
            or not all(isinstance(c, int) and 0 <= c < channels for c in used):
        raise ValueError(f'channels_used must list distinct channels 0..{channels - 1}, '
                         f'got {used!r}')
    if 'genome' in manifest and (not isinstance(manifest['genome'], list)
                                 or not all(_is_number(g) for g in manifest['genome'])):
        raise ValueError('genome must be a list of numbers')
    samples = manifest.get('samples', 0)
    if not isinstance(samples, int) or isinstance(samples, bool) or samples < 0:
        raise ValueError(f'samples must be a count >= 0, got {samples!r}')
    lost = manifest.get('lost_steps', [])
    if not isinstance(lost, list) or not all(
            isinstance(p, (list, tuple)) and len(p) == 2
            and all(isinstance(v, int) and v >= 0 for v in p)
            for p in lost):
        raise ValueError(f'lost_steps must list [episode, step] pairs, got {lost!r}')
    low, high = reading_range(manifest, channels)
    if not low < high:
        raise ValueError(f'reading_range must be [low, high] with low < high, got {[low, high]}')


def reading_range(manifest: dict, channels: int) -> tuple[float, float]:
    """Allowed readings: the manifest's ``reading_range``, else 0..525 on a Khepera."""
    if 'reading_range' in manifest:
        value = manifest['reading_range']
        if not isinstance(value, list) or len(value) != 2 or not all(map(_is_number, value)):
            raise ValueError(f'reading_range must be [low, high], got {value!r}')
        return float(value[0]), float(value[1])
    return KHEPERA_RANGE if channels == KHEPERA_CHANNELS else (-math.inf, math.inf)


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value)


def finish_manifest(rec: Recording) -> dict:
    """The manifest to write: the given keys plus channels, samples and lost steps.

    Lost steps are the gaps in the data plus any the recorder declared (steps lost
    after an episode's last sample leave no gap).
    """
    manifest = dict(rec.manifest)
    if rec.channels != KHEPERA_CHANNELS:
        manifest['channels'] = rec.channels
    manifest['samples'] = len(rec)
    lost, duplicated = rec.step_problems()
    if duplicated:
        raise RecordingError(f'steps recorded twice: {_pairs(duplicated)}')
    declared = {tuple(p) for p in manifest.get('lost_steps', [])}
    manifest['lost_steps'] = [list(p) for p in sorted(declared | set(lost))]
    return manifest


def _pairs(pairs: list[tuple[int, int]], limit: int = 5) -> str:
    text = ', '.join(f'(episode {e}, step {s})' for e, s in pairs[:limit])
    return text + (f' and {len(pairs) - limit} more' if len(pairs) > limit else '')


# -- rows -------------------------------------------------------------------------------

def first_bad_row(rec: Recording) -> tuple[int, str] | None:
    """(index, problem) of the first sample that breaks the format, or None."""
    manifest, n = rec.manifest, len(rec)
    low, high = reading_range(manifest, rec.channels)
    used = rec.readings[:, rec.channels_used]
    known = ~np.isnan(rec.direction)
    checks = (
        ((rec.episode < 0) | (rec.step < 0),
         lambda i: f'episode and step must be >= 0, got {rec.episode[i]}, {rec.step[i]}'),
        (~np.isin(rec.condition, list(manifest['conditions'])),
         lambda i: f'condition {str(rec.condition[i])!r} is not in the manifest conditions '
                   f'{sorted(manifest["conditions"])}'),
        (np.isinf(rec.heading_deg), lambda i: 'heading_deg must be finite or empty'),
        (~((used >= low) & (used <= high)).all(axis=1),       # NaN fails too
         lambda i: _bad_reading(rec, i, low, high)),
        (known != ~np.isnan(rec.power),
         lambda i: 'direction and power must both be given or both be empty'),
        (known & (~np.isin(rec.direction, (-1, 1)) | ~np.isin(rec.power, np.arange(10))),
         lambda i: f'direction must be -1 or +1 and power 0..9, got {rec.direction[i]:g}, '
                   f'{rec.power[i]:g}'),
    )
    bad = [(int(np.argmax(mask)), message) for mask, message in checks if n and mask.any()]
    if not bad:
        return None
    i, message = min(bad, key=lambda b: b[0])
    return i, message(i)


def _bad_reading(rec: Recording, i: int, low: float, high: float) -> str:
    for c in rec.channels_used:
        value = rec.readings[i, c]
        if math.isnan(value):
            return f's{c} is empty but channels_used includes it'
        if not low <= value <= high:
            return f's{c} must be a reading in [{low:g}, {high:g}], got {value:g}'
    return 'bad reading'


# -- CSV ----------------------------------------------------------------------------------

def paths(path) -> tuple[Path, Path]:
    """(NAME.csv, NAME.yaml) for NAME, NAME.csv or NAME.yaml."""
    path = Path(path)
    stem = path.with_suffix('') if path.suffix in ('.csv', '.yaml') else path
    return stem.with_name(stem.name + '.csv'), stem.with_name(stem.name + '.yaml')


def write_csv(rec: Recording, path) -> tuple[Path, Path]:
    """Write NAME.csv and NAME.yaml; returns their paths."""
    rec.check()
    csv_path, yaml_path = paths(path)
    manifest = finish_manifest(rec)
    csv_path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_open(csv_path, newline='') as f:      # the old file stays until complete
        writer = csv.writer(f, lineterminator='\n')
        writer.writerow(columns(rec.channels))
        for i in range(len(rec)):
            writer.writerow([int(rec.episode[i]), int(rec.step[i]), _cell(rec.heading_deg[i]),
                             str(rec.condition[i])] + [_cell(v) for v in rec.readings[i]]
                            + [_cell(rec.direction[i]), _cell(rec.power[i])])
    atomic_write_text(yaml_path, dump_manifest(manifest))
    return csv_path, yaml_path


def dump_manifest(manifest: dict) -> str:
    return yaml.safe_dump(_plain(manifest), sort_keys=False, default_flow_style=None)


def _plain(value):
    """numpy scalars and tuples to YAML-safe Python values."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _cell(value) -> str:
    """A number as the shortest text that reads back exactly; empty for NaN."""
    value = float(value)
    if math.isnan(value):
        return ''
    if value.is_integer() and abs(value) < 1e15:
        return str(int(value))
    return repr(value)


def read_manifest(path) -> dict:
    """The YAML manifest, or a RecordingError with the file and line."""
    path = Path(path)
    try:
        manifest = yaml.safe_load(path.read_text())
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        line = f' line {mark.line + 1}' if mark is not None else ''
        raise RecordingError(f'{path}{line}: not valid YAML: {exc.problem}') from None
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise RecordingError(f'{path}: not valid YAML: {" ".join(str(exc).split())}') from None
    return manifest


def read_csv(path) -> Recording:
    """Read NAME.csv with NAME.yaml (NAME, NAME.csv or NAME.yaml may be given)."""
    csv_path, yaml_path = paths(path)
    for p in (csv_path, yaml_path):
        if not p.is_file():
            raise FileNotFoundError(f'{p}: no such file (a recording is NAME.csv plus '
                                    f'NAME.yaml)')
    manifest = read_manifest(yaml_path)
    try:
        with open(csv_path, newline='') as f:
            reader = csv.reader(f, strict=True)
            channels = _read_header(csv_path, next(reader, None))
            try:
                check_manifest(manifest, channels)
            except ValueError as exc:
                raise RecordingError(f'{yaml_path}: {exc}') from None
            lines, rows = [], []
            for row in reader:
                lines.append(reader.line_num)
                rows.append(_parse_row(f'{csv_path} line {reader.line_num}', row, channels))
    except UnicodeDecodeError as exc:
        raise RecordingError(f'{csv_path}: not a text file ({exc.reason})') from None
    except csv.Error as exc:
        raise RecordingError(f'{csv_path} line {reader.line_num}: {exc}') from None
    rec = _assemble(rows, channels, manifest)
    where = (lambda i: f'{csv_path} line {lines[i]}')
    bad = first_bad_row(rec)
    if bad:
        raise RecordingError(f'{where(bad[0])}: {bad[1]}')
    check_sequence(rec, where, str(csv_path), yaml_path.name)
    return rec


def _read_header(path: Path, header: list[str] | None) -> int:
    """The number of light channels the header declares."""
    if header is None:
        raise RecordingError(f'{path}: empty file, expected the header {",".join(COLUMNS)}')
    channels = len(header) - len(COLUMNS) + KHEPERA_CHANNELS
    if channels < 1 or tuple(header) != columns(channels):
        raise RecordingError(f'{path} line 1: header must be {",".join(COLUMNS)} (with s8, '
                             f's9, ... for more channels), got {",".join(header)}')
    return channels


def _parse_row(where: str, row: list[str], channels: int) -> tuple:
    names = columns(channels)
    if len(row) != len(names):
        raise RecordingError(f'{where}: expected {len(names)} columns, got {len(row)}')
    try:
        return tuple(_number(n, t, integer=n in ('episode', 'step')) if n != 'condition' else t
                     for n, t in zip(names, row))
    except ValueError as exc:
        raise RecordingError(f'{where}: {exc}') from None


def _number(name: str, text: str, integer: bool = False) -> float:
    if text == '':
        if integer:
            raise ValueError(f'{name} is empty')
        return math.nan
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f'{name} is not a number: {text!r}') from None
    if integer and not value.is_integer():
        raise ValueError(f'{name} must be an integer, got {text!r}')
    return value


def _assemble(rows: list[tuple], channels: int, manifest: dict) -> Recording:
    table = np.array([r[:3] + r[4:] for r in rows], np.float64).reshape(len(rows), channels + 5)
    return Recording(
        episode=table[:, 0].astype(np.int64), step=table[:, 1].astype(np.int64),
        heading_deg=table[:, 2], condition=np.array([r[3] for r in rows], dtype=str),
        readings=table[:, 3:3 + channels].copy(), direction=table[:, -2].copy(),
        power=table[:, -1].copy(), manifest=manifest)


def check_sequence(rec: Recording, where, name: str, manifest_name) -> None:
    """Every (episode, step) once, in order within its episode, as the manifest declares.

    ``where(i)`` names sample i (a line or a message) in errors.
    """
    last: dict[int, int] = {}
    first: dict[tuple[int, int], int] = {}
    for i, (e, s) in enumerate(zip(rec.episode.tolist(), rec.step.tolist())):
        if (e, s) in first:
            raise RecordingError(f'{where(i)}: duplicate sample (episode {e}, step {s}), '
                                 f'first at {where(first[e, s])}')
        if s < last.get(e, -1):
            raise RecordingError(f'{where(i)}: step {s} of episode {e} comes after step '
                                 f'{last[e]}')
        first[e, s] = i
        last[e] = s
    samples = rec.manifest.get('samples')
    if samples is not None and samples != len(rec):
        raise RecordingError(f'{name}: {manifest_name} says {samples} samples, found '
                             f'{len(rec)} (truncated or extended?)')
    if 'lost_steps' in rec.manifest:
        declared = {tuple(p) for p in rec.manifest['lost_steps']}
        missing = [p for p in rec.step_problems()[0] if p not in declared]
        if missing:
            raise RecordingError(f'{name}: steps missing that {manifest_name} does not list '
                                 f'as lost: {_pairs(missing)}')


# -- either format ------------------------------------------------------------------------

def load(path) -> Recording:
    """Read a recording: a rosbag2 directory, or NAME / NAME.csv / NAME.yaml."""
    path = Path(path)
    if path.is_dir():
        from .bag import read_bag
        return read_bag(path)
    return read_csv(path)


def bag_path(path) -> Path:
    """Where the rosbag2 twin of recording NAME goes: NAME_bag/."""
    stem = paths(path)[0].with_suffix('')
    return stem.with_name(stem.name + '_bag')
