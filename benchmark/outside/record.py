"""A case's 'real' recording, written as a user with a real robot would write it."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from khepera_noise_ros.recording import write_csv

from . import robot


def make_recording(case: dict, quick: bool, folder: Path) -> Path:
    """Write the case's 'real' recording; returns its path (NAME without suffix)."""
    rng = np.random.default_rng([case['seed'], 7])
    if case['protocol'] == 'closed_loop':
        rec = robot.closed_loop(case['seed'], case['effects'], 10 if quick else 20, rng)
    else:
        headings = (-30.0, 0.0, 45.0) if quick else (-60.0, -20.0, 0.0, 30.0, 90.0)
        _, rec = robot.stationary(case['seed'], case['effects'], headings, 60, rng)
    path = folder / 'real'
    write_csv(rec, path)
    return path
