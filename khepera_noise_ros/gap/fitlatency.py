"""The sensor set of a closed-loop latency from a tracked robot's headings: the sensors
whose readings fit best at an earlier heading (``gap.headinglag``).

A sensor's turn response shows a latency only where the turn moves its light; the
heading residuals say which sensors read an earlier heading, and by how many steps.
See docs/diagnosis.md ("Heading residuals at each sensor's delay").
"""
from __future__ import annotations

import numpy as np

from . import headinglag, replay


def heading_delays(recordings) -> np.ndarray | None:
    """Per sensor, the delay (steps) at which its heading residuals are least, from the
    tracked closed-loop recordings (the median over them); None without one."""
    found = []
    for rec in recordings:
        if replay.kind(rec) != 'closed_loop' or not np.isfinite(rec.heading_deg).all():
            continue
        episodes, ep = np.unique(rec.episode, return_inverse=True)
        order = np.lexsort((rec.step, ep))
        ep, steps = ep[order], rec.step[order]
        pair = np.r_[False, (ep[1:] == ep[:-1]) & (steps[1:] == steps[:-1] + 1)]
        _, use, lag = headinglag.residuals(rec.readings[order][:, :8].astype(np.float64),
                                           rec.heading_deg[order], rec.condition[order],
                                           pair, episodes.size)
        if use.any():
            found.append(lag)
    return np.median(found, axis=0).round().astype(np.int64) if found else None


def delayed_sensors(recordings) -> tuple:
    """The sensors whose readings take an earlier heading (empty when none or untracked)."""
    lag = heading_delays(recordings)
    return () if lag is None else tuple(int(k) for k in np.flatnonzero(lag > 0))
