"""Recordings as NAME.csv plus its NAME.yaml manifest: writing and strict reading."""
from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any, Callable, SupportsFloat

import numpy as np
import yaml

from ..files import StrPath, atomic_open, atomic_write_text
from .model import (COLUMNS, KHEPERA_CHANNELS, Recording, RecordingError, check_manifest,
                    check_sequence, columns, dump_manifest, finish_manifest, first_bad_row)

EXACT = 2 ** 53                  # the largest integer a double holds exactly: episode and step


def paths(path: StrPath) -> tuple[Path, Path]:
    """(NAME.csv, NAME.yaml) for NAME, NAME.csv or NAME.yaml."""
    path = Path(path)
    stem = path.with_suffix('') if path.suffix in ('.csv', '.yaml') else path
    return stem.with_name(stem.name + '.csv'), stem.with_name(stem.name + '.yaml')


def write_csv(rec: Recording, path: StrPath) -> tuple[Path, Path]:
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


def _cell(value: SupportsFloat) -> str:
    """A number as the shortest text that reads back exactly; empty for NaN."""
    value = float(value)
    if math.isnan(value):
        return ''
    if value.is_integer() and abs(value) < 1e15:
        return str(int(value))
    return repr(value)


def read_manifest(path: StrPath) -> Any:
    """The YAML manifest (not yet checked: ``check_manifest`` does), or a RecordingError
    with the file and line."""
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


def read_csv(path: StrPath) -> Recording:
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
            lines: list[int] = []
            rows: list[tuple[float | str, ...]] = []
            for row in reader:
                lines.append(reader.line_num)
                rows.append(_parse_row(f'{csv_path} line {reader.line_num}', row, channels))
    except UnicodeDecodeError as exc:
        raise RecordingError(f'{csv_path}: not a text file ({exc.reason})') from None
    except csv.Error as exc:
        raise RecordingError(f'{csv_path} line {reader.line_num}: {exc}') from None
    rec = _assemble(rows, channels, manifest)
    where: Callable[[int], str] = (lambda i: f'{csv_path} line {lines[i]}')
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


def _parse_row(where: str, row: list[str], channels: int) -> tuple[float | str, ...]:
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
    if integer and not (value.is_integer() and abs(value) <= EXACT):
        raise ValueError(f'{name} must be an integer of at most {EXACT:,} in size, got {text!r}')
    return value


def _assemble(rows: list[tuple[float | str, ...]], channels: int, manifest: dict[str, Any]
              ) -> Recording:
    table = np.array([r[:3] + r[4:] for r in rows], np.float64).reshape(len(rows), channels + 5)
    return Recording(
        episode=table[:, 0].astype(np.int64), step=table[:, 1].astype(np.int64),
        heading_deg=table[:, 2], condition=np.array([r[3] for r in rows], dtype=str),
        readings=table[:, 3:3 + channels].copy(), direction=table[:, -2].copy(),
        power=table[:, -1].copy(), manifest=manifest)
