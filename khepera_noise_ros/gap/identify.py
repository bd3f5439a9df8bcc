"""The simulator's world identified before its noise: the world model's parts fitted in
order, each given those before it (the light shapes what a sensor follows, and both what a
turn shows), then dropped while dropping one lowers the held-out discrepancy; kept when
the set lowers it significantly (the rules: docs/identification.md)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

from ..effects import WORLD_MODEL, Effect
from .compare import Comparison, paired_p
from .select import FINGERPRINT_REPLICATES, STEP_ALPHA, fit_one
from .target import Target


@dataclass
class World:
    effects: list[Effect]
    before: float                     # held-out discrepancy of the stock simulator
    after: float                      # ... with the world identified
    p_value: float
    notes: dict[str, str] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {'effects': [{'name': e.name, 'sensors': list(e.sensors),
                             'parameters': e.parameters()} for e in self.effects],
                'discrepancy_before': self.before, 'discrepancy_after': self.after,
                'heldout_reduction': 1.0 - self.after / self.before if self.before > 0 else 0.0,
                'p_value': self.p_value, 'notes': self.notes}


def world_model(a: Target, b: Target, before: Comparison, names: Sequence[str],
                log: Callable[[str], None] | None = None,
                notes: dict[str, str] | None = None) -> World | None:
    """The world model's parts among ``names`` fitted on ``a`` and judged on ``b``
    (``before``: ``b`` against the stock simulator); None when none is kept.  ``notes``
    gets each part's note (what it found, or the protocol it lacks)."""
    fitted: list[Effect] = []
    notes = {} if notes is None else notes
    for name in (n for n in WORLD_MODEL if n in names):
        given = a.with_given(fitted)
        cand = fit_one(name, given, given.compare(replicates=FINGERPRINT_REPLICATES))
        notes[name] = cand.note
        if cand.effect is not None:
            fitted.append(cand.effect)
    if not fitted:
        return None
    current = b.compare(fitted)
    while fitted:                 # drop the part whose absence the held-out data prefer
        trials = [(b.compare(fitted[:i] + fitted[i + 1:]), i) for i in range(len(fitted))]
        best, i = min(trials, key=lambda t: t[0].discrepancy)
        if best.discrepancy >= current.discrepancy:
            break
        notes[fitted[i].name] += '; dropped: the held-out data are closer without it'
        fitted.pop(i)
        current = best
    if not fitted:
        return None
    p = paired_p(b.replicate_discrepancies(before), b.replicate_discrepancies(current),
                 before.discrepancy, current.discrepancy)
    if p >= STEP_ALPHA or current.discrepancy >= before.discrepancy:
        return None
    if log:
        log(f'world: {", ".join(e.name for e in fitted)} -> '
            f'{1 - current.discrepancy / before.discrepancy:.2f}')
    return World(fitted, before.discrepancy, current.discrepancy, p, notes)
