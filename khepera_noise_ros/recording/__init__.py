"""Recordings in the public format: CSV plus YAML manifest, and rosbag2 (MCAP).

``model`` is the in-memory ``Recording`` and its manifest, ``csv`` and ``bag`` the two
file formats; ``load`` reads either.
"""
from __future__ import annotations

from pathlib import Path

from ..files import StrPath
from .csv import paths, read_csv, read_manifest, write_csv
from .model import (COLUMNS, FORMAT, KHEPERA_CHANNELS, KHEPERA_RANGE, PROTOCOLS, SOURCES,
                    Recording, RecordingError, check_manifest, check_sequence, columns,
                    concatenate, dump_manifest, finish_manifest, first_bad_row,
                    from_trace, reading_range)

__all__ = ['COLUMNS', 'FORMAT', 'KHEPERA_CHANNELS', 'KHEPERA_RANGE', 'PROTOCOLS', 'SOURCES',
           'Recording', 'RecordingError', 'bag_path', 'check_manifest', 'check_sequence',
           'columns', 'concatenate', 'dump_manifest', 'finish_manifest', 'first_bad_row',
           'from_trace', 'load', 'paths', 'read_csv', 'read_manifest', 'reading_range',
           'write_csv']


def load(path: StrPath) -> Recording:
    """Read a recording: a rosbag2 directory, or NAME / NAME.csv / NAME.yaml."""
    path = Path(path)
    if path.is_dir():
        from .bag import read_bag      # rosbags only for bag users
        return read_bag(path)
    return read_csv(path)


def bag_path(path: StrPath) -> Path:
    """Where the rosbag2 twin of recording NAME goes: NAME_bag/."""
    stem = paths(path)[0].with_suffix('')
    return stem.with_name(stem.name + '_bag')
