"""Made-up comparisons for the selection's rules: what the fakes of a ``Target`` share."""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..effects.base import Array, Key
from ..gap.compare import MARGIN, Comparison


def replicate_discrepancies(keys: Sequence[Key], reps: Array, c: Comparison) -> Array:
    """``Target.replicate_discrepancies`` of real bootstrap replicates ``reps`` (R, K), one
    column per key of ``keys``, against the simulated side of ``c``."""
    z = (reps[:, [list(keys).index(k) for k in c.keys]] - c.sim[None]) / c.se[None]
    out: Array = (np.clip(np.abs(z) - MARGIN, 0.0, None) ** 2).sum(axis=1)
    return out
