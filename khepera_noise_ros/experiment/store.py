"""The resumable results store: one JSON file per finished unit of work.

A unit is one (condition, trial, step).  Each is written atomically (a
temporary file renamed into place), so a run killed at any moment leaves
either the whole file or none; temporary files are never read.  Every file
carries the hash of the settings that made it, and a directory made with
other settings is refused rather than mixed.

An evolution still running is checkpointed as the log of fitness values its
EA was told: replaying them on a fresh EA with the same seed restores it
exactly, so a resumed run continues mid-phase with nothing recomputed.

Layout under the output directory::

    config.yaml                          settings used, with their hash
    units/<condition>/trial-NN/stepK.json              a finished unit
    units/<condition>/trial-NN/stepK.checkpoint.json   an unfinished evolution
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import yaml

from ..files import atomic_open, atomic_write_text, write_json

UNIT_FORMAT = 'khepera-noise-replicate-unit/1'
CHECKPOINT_FORMAT = 'khepera-noise-replicate-checkpoint/1'
SESSIONS_FORMAT = 'khepera-noise-replicate-sessions/1'
OUTPUTS = ('config.yaml', 'sessions.json', 'report.md', 'results.json', 'results.csv', 'fig8.png',
           'curves.png')


class SettingsMismatch(ValueError):
    """The directory holds results made with other settings."""


class Store:
    def __init__(self, root, config_hash: str):
        self.root = Path(root)
        self.hash = config_hash
        self.units = self.root / 'units'

    def open(self, config_yaml: str, fresh: bool = False) -> int:
        """Check the directory can take these settings, write them; returns units found.

        ``fresh`` discards earlier results first (only the files this store writes).
        """
        if fresh:
            self.clear()
        found = self._files('step*.json')
        written = self.root / 'config.yaml'
        if found:
            old = _hash_of(written) if written.exists() else None
            if old != self.hash:
                raise SettingsMismatch(
                    f'{self.root} holds results made with other settings (hash {old} there, '
                    f'{self.hash} now); resume with the same settings, add --fresh to discard '
                    f'them, or choose another --out')
        else:
            (self.root / 'sessions.json').unlink(missing_ok=True)
        atomic_write_text(written, config_yaml)
        return sum(1 for p in found if not p.name.endswith('.checkpoint.json'))

    def checkpoints(self) -> list[Path]:
        """Evolutions saved part-way (their unit is not finished yet)."""
        return self._files('step*.checkpoint.json')

    def _files(self, pattern: str) -> list[Path]:
        return sorted(self.units.rglob(pattern)) if self.units.exists() else []

    def clear(self) -> None:
        if self.units.exists():
            shutil.rmtree(self.units)
        for name in OUTPUTS:
            (self.root / name).unlink(missing_ok=True)
        for png in self.root.glob('fig*.png'):
            png.unlink()

    def path(self, condition: str, trial: int, step, suffix: str = '') -> Path:
        return self.units / condition / f'trial-{trial + 1:02d}' / f'step{step}{suffix}.json'

    def load(self, condition: str, trial: int, step) -> dict | None:
        """The finished unit, or None if it is not (validly) there."""
        return self._read(self.path(condition, trial, step), UNIT_FORMAT)

    def save(self, condition: str, trial: int, step, result: dict) -> None:
        unit = {'format': UNIT_FORMAT, 'config_hash': self.hash, 'condition': condition,
                'trial': trial, 'step': step, **result}
        write_unit(self.path(condition, trial, step), unit)
        self.path(condition, trial, step, '.checkpoint').unlink(missing_ok=True)

    def load_checkpoint(self, condition: str, trial: int, step) -> list[float]:
        data = self._read(self.path(condition, trial, step, '.checkpoint'), CHECKPOINT_FORMAT)
        return [] if data is None else list(data['told'])

    def save_checkpoint(self, condition: str, trial: int, step, told: list[float]) -> None:
        write_unit(self.path(condition, trial, step, '.checkpoint'),
                   {'format': CHECKPOINT_FORMAT, 'config_hash': self.hash, 'told': told})

    def sessions(self) -> list[dict]:
        """Earlier sessions of this run: how long each took and whether it finished."""
        data = self._read(self.root / 'sessions.json', SESSIONS_FORMAT)
        return [] if data is None else data['sessions']

    def record_session(self, elapsed_s: float, finished: bool, backend: dict) -> list[dict]:
        sessions = self.sessions() + [{'elapsed_s': round(elapsed_s, 2), 'finished': finished,
                                       'backend': backend}]
        write_json(self.root / 'sessions.json', {'format': SESSIONS_FORMAT,
                                                 'config_hash': self.hash, 'sessions': sessions})
        return sessions

    def _read(self, path: Path, fmt: str) -> dict | None:
        try:
            data = json.loads(path.read_text())
        except FileNotFoundError:
            return None
        except (OSError, ValueError):
            return None          # not ours or damaged by hand: recompute and overwrite it
        if not isinstance(data, dict) or data.get('format') != fmt:
            return None
        if data.get('config_hash') != self.hash:
            raise SettingsMismatch(f'{path} was made with other settings (hash '
                                   f"{data.get('config_hash')}, now {self.hash}); add --fresh "
                                   f'to discard the old results')
        return data


def write_unit(path: Path, data: dict) -> None:
    """Write a unit or checkpoint atomically (a temporary file renamed into place) but
    without fsync: hundreds of fsyncs cost seconds on a busy disk, and a file that a
    power cut leaves empty or cut short is not valid JSON, which ``_read`` takes as not
    there, so the unit is simply computed again."""
    with atomic_open(path, fsync=False) as f:
        json.dump(data, f, default=_listed)


def _listed(obj):
    if hasattr(obj, 'tolist'):          # numpy arrays and scalars
        return obj.tolist()
    raise TypeError(f'cannot write {type(obj).__name__} as JSON')


def _hash_of(config_path: Path) -> str | None:
    try:
        return (yaml.safe_load(config_path.read_text()) or {}).get('hash')
    except (OSError, yaml.YAMLError, AttributeError):
        return None
