"""The sensor set of a closed-loop latency from a tracked robot's headings
(``gap.headinglag``): every sensor but those that clearly read the heading of the
moment.

A sensor's turn response shows a latency only where the turn moves its light; the
heading residuals say which sensors read an earlier heading and which clearly do not.
See docs/diagnosis.md ("Heading residuals at each sensor's delay").
"""
from __future__ import annotations

import numpy as np

from . import closednoise, headinglag, replay


def delayed_sensors(recordings) -> tuple:
    """The sensors a latency may act on, from the tracked closed-loop recordings: all but
    those whose readings clearly fit best at the heading they are read at (a sensor on a
    flat stretch of light may lag unseen, and shared noise carries its delay); empty when
    no sensor clearly reads an earlier heading, or without headings."""
    late, now = np.zeros(8, bool), np.zeros(8, bool)
    for rec in recordings:
        if replay.kind(rec) != 'closed_loop' or not np.isfinite(rec.heading_deg).all():
            continue
        episodes, _, order, _, pair = closednoise.ordered(rec)
        var = headinglag.variances(rec.readings[order][:, :8].astype(np.float64),
                                   rec.heading_deg[order], rec.condition[order], pair,
                                   episodes.size)
        if var is not None:
            late |= headinglag.delayed(var)
            now |= headinglag.prompt(var)
    return tuple(int(k) for k in np.flatnonzero(~now)) if late.any() else ()
