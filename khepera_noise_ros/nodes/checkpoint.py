"""Crash-proof evolution: the fitness of every batch, written atomically after each generation.

The EA draws all its randomness from its seed, so a run is fully determined by
its configuration and the fitness values it was told, batch by batch.  A
``Checkpoint`` records those values (with a digest of the genomes and seeds
each batch asked for) and is written with an atomic rename, so a crash at any
moment leaves the previous complete checkpoint or the new one, never half of
one.  To resume, the EAs are rebuilt from the same configuration and the
recorded batches are answered from the file instead of being evaluated again:
the run continues exactly where it stopped, and ends exactly as an
uninterrupted run would.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Callable

import numpy as np

from ..files import remove_leftovers, write_json

FORMAT = 'khepera-noise-evolution-checkpoint/1'
Evaluate = Callable[[np.ndarray, np.ndarray], np.ndarray]


def digest(genomes: np.ndarray, seeds: np.ndarray) -> str:
    """A short fingerprint of one batch request."""
    h = hashlib.blake2b(digest_size=8)
    h.update(np.ascontiguousarray(genomes, np.float64).tobytes())
    h.update(np.ascontiguousarray(seeds, np.int64).tobytes())
    return h.hexdigest()


def checkpoint_path(results_path: str, checkpoint_path: str) -> Path | None:
    """The checkpoint file: as given, else beside the results (``X.checkpoint.json``),
    else none."""
    if checkpoint_path:
        return Path(checkpoint_path)
    if results_path:
        path = Path(results_path)
        return path.with_name(path.stem + '.checkpoint.json')
    return None


class Checkpoint:
    """The batches of one run so far; ``evaluator(evaluate)`` records new batches and
    answers recorded ones (a resumed run replays them)."""

    def __init__(self, path: Path, config: dict):
        self.path, self.config = Path(path), config
        self.batches: list[dict] = []       # {'digest': str, 'fitness': [...]}
        self.state: dict = {}               # what the last save said besides the batches
        self.loaded = 0                     # batches read from the file
        self.calls = 0                      # batches asked for so far

    @property
    def replaying(self) -> bool:
        """Are batches read from the file still to be answered?"""
        return self.calls < self.loaded

    def load(self) -> bool:
        """Read the file if there is one; True if it holds a run of this configuration.
        ValueError if it holds another run (its differences named) or is not a checkpoint."""
        if not self.path.is_file():
            return False
        try:
            data = json.loads(self.path.read_text())
        except (OSError, ValueError) as exc:      # UnicodeDecodeError, JSONDecodeError
            raise ValueError(f'checkpoint {self.path} cannot be read: {exc}') from None
        if not isinstance(data, dict) or data.get('format') != FORMAT:
            raise ValueError(f'{self.path} is not a {FORMAT} file')
        theirs = data.get('config', {})
        if not isinstance(theirs, dict):
            raise ValueError(f'checkpoint {self.path} is damaged: its config is not a mapping')
        differ = sorted(k for k in set(theirs) | set(self.config)
                        if theirs.get(k) != self.config.get(k))
        if differ:         # the names escaped as in JSON: one line whatever a key holds
            names = ', '.join(json.dumps(k, ensure_ascii=False)[1:-1] for k in differ)
            raise ValueError(f'checkpoint {self.path} belongs to another run (it differs in '
                             f'{names}); set resume to false to start afresh and '
                             'overwrite it, or choose another checkpoint_path')
        batches = data.get('batches')
        if not isinstance(batches, list) or not all(
                isinstance(b, dict) and isinstance(b.get('digest'), str)
                and isinstance(b.get('fitness'), list) for b in batches):
            raise ValueError(f'checkpoint {self.path} is damaged: its batches must be a list '
                             'of {digest, fitness}; set resume to false to start afresh')
        self.batches = batches
        self.loaded = len(self.batches)
        self.state = {k: v for k, v in data.items() if k not in ('format', 'config', 'batches')}
        return True

    def evaluator(self, evaluate: Evaluate) -> Evaluate:
        """``evaluate`` behind the record: recorded batches first, checked against their
        digest, then every new batch is evaluated and recorded."""
        def run(genomes, seeds) -> np.ndarray:
            key = digest(genomes, seeds)
            if self.replaying:
                batch = self.batches[self.calls]
                if batch['digest'] != key:
                    raise ValueError(f'checkpoint {self.path} does not fit this run: batch '
                                     f'{self.calls} asked for other genomes or seeds than '
                                     'were recorded')
                self.calls += 1
                return np.asarray(batch['fitness'], np.float64)
            fitness = np.asarray(evaluate(genomes, seeds), np.float64)
            self.batches.append({'digest': key, 'fitness': fitness.tolist()})
            self.calls += 1
            return fitness
        return run

    def save(self, **state) -> None:
        """Write every batch so far, and ``state`` (generation, history...), atomically."""
        self.state = state
        write_json(self.path, {'format': FORMAT, 'config': self.config, **state,
                               'batches': self.batches})

    def remove(self) -> None:
        """The finished run's checkpoint, and any temporary a killed writer left beside it."""
        self.path.unlink(missing_ok=True)
        remove_leftovers(self.path)
