"""Made-up comparisons for the selection's rules: what the fakes of a ``Target`` share."""
from __future__ import annotations

from typing import Sequence

from ..effects.base import Array, Key
from ..gap import compare
from ..gap.compare import Comparison


def replicate_discrepancies(keys: Sequence[Key], reps: Array, c: Comparison) -> Array:
    """``Target.replicate_discrepancies`` of real bootstrap replicates ``reps`` (R, K), one
    column per key of ``keys``, against the simulated side of ``c``."""
    return compare.replicate_discrepancies(reps[:, [list(keys).index(k) for k in c.keys]], c)
