"""Real recordings split into a part to fit on and a part held out (by episode, or by
condition)."""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..recording import Recording


def by_episode(rec: Recording) -> tuple[np.ndarray, np.ndarray]:
    """(fit, held-out) boolean masks over the samples: alternate episodes of each condition,
    or the first and second half of a condition's only episode."""
    fit = np.zeros(len(rec), bool)
    for label in rec.conditions():
        here = rec.condition == label
        episodes = np.unique(rec.episode[here])
        if episodes.size >= 2:
            fit |= here & np.isin(rec.episode, episodes[::2])
        else:
            steps = rec.step[here]
            fit[here] = steps <= np.median(steps)
    return fit, ~fit


def split(recordings: Sequence[Recording], held_out: Sequence[str] | None = None
          ) -> tuple[list[tuple[int, Recording]], list[tuple[int, Recording]]]:
    """(fit, held-out) lists of (source index, part); a recording's empty side left out."""
    fit: list[tuple[int, Recording]] = []
    test: list[tuple[int, Recording]] = []
    for i, rec in enumerate(recordings):
        out = np.isin(rec.condition, list(held_out)) if held_out else by_episode(rec)[1]
        for side, mask in ((fit, ~out), (test, out)):
            if mask.any():
                side.append((i, rec.select(mask)))
    return fit, test


def check_conditions(recordings: Sequence[Recording], held_out: Sequence[str]) -> None:
    """Every held-out condition must exist, and some condition must remain to fit on."""
    known = sorted({c for r in recordings for c in r.conditions()})
    missing = [c for c in held_out if c not in known]
    if missing:
        raise ValueError(f'held-out condition(s) {missing} are not in the recordings; '
                         f'conditions: {known}')
    if set(known) <= set(held_out):
        raise ValueError(f'holding out every condition ({known}) leaves nothing to fit on')
