"""Fitting ``actuator_turn_error``: a turn's scale, its random slip and its creep.

Fingerprints: the readings' response to a turn scaled (``turn_response``,
``sensor_turn_response``), the turn size itself where headings are recorded
(``turn_size``), and, for a zero-mean random error, which leaves those alone, the
scatter of the turn (``turn_scatter``, ``turn_size_scatter``, by power band;
``gap.turnscatter``).  Scale, slip and creep (a slip of fixed size, fitted only
where the power-0 band shows scatter) are fitted jointly by golden-section search,
one after the other, the scale and creep once more.  Scale 1 is kept when it fits as well.
"""
from __future__ import annotations

import numpy as np

from . import effects as fx
from . import loopchange
from .fitbase import Z_DETECT, Candidate, golden, rows
from .target import Target
from .turnscatter import BANDS, band_label
from .where import Comparison

SCATTER = ('turn_scatter', 'turn_size_scatter')
FAMILIES = ('turn_response', 'sensor_turn_response', 'turn_size') + SCATTER
SLIP_MAX = 0.8           # sd of the slip per degree turned searched over
CREEP_MAX = 10.0         # degrees per step searched over
KINDS = ('closed_loop',)
SAME = 0.02              # relative objective within which the simpler effect is kept


def actuator(target: Target, c: Comparison) -> Candidate:
    name = fx.ActuatorTurnError.name
    response = [(r, s) for k, r, s, se, z in rows(c, 'turn_response') if k.part == 'lag 0']
    if not response:
        return Candidate(name, None, 'no closed-loop data: turns cannot be checked')
    # a random error only adds scatter: less than simulated is no fingerprint of it
    flagged = {f: [k for k, *_, z in rows(c, f)
                   if (z if f in SCATTER else abs(z)) > Z_DETECT] for f in FAMILIES}
    if not any(flagged.values()):
        return Candidate(name, None, 'the readings respond to turns as simulated')
    # recorded headings measure the turn itself; else the readings' response to it, at
    # both lags (least squares): with a latency given, the lag-0 response is noise alone
    size = [(r, s) for k, r, s, se, z in rows(c, 'turn_size')]
    pairs = np.array(size if size else [(r, s) for k, r, s, *_ in rows(c, 'turn_response')],
                     np.float64)
    pairs = pairs[np.isfinite(pairs).all(axis=1)]
    real, sim = pairs.T if pairs.size else (np.zeros(1), np.zeros(1))
    ratio = float(real @ sim / (sim @ sim)) if sim @ sim > 1e-18 else 1.0
    scale0 = float(np.clip(ratio, 0.2, 2.0))
    still = band_label(BANDS[0])
    creep_seen = any(k.part == still for f in SCATTER
                     for k in flagged[f])

    # beside a latency, not the change residuals: what the latency leaves there pulls the
    # scale the wrong way (``gap.loopchange``)
    present = {k.family for k in target.real.keys}
    lagged = any(e.name == fx.SensorLatency.name for e in target.given)
    families = present - loopchange.FAMILIES if lagged and present & loopchange.FAMILIES \
        else None

    def objective(scale, slip, creep=0.0):
        return target.objective([fx.ActuatorTurnError(scale, slip, creep=creep)], KINDS,
                                families)
    # the creep first where power 0 shows it (there the slip cannot act), then the
    # slip given it, the scale once more, and the creep given both
    scale = golden(lambda x: objective(x, 0.0), scale0 * 0.7, scale0 * 1.45, 8)
    creep = _creep(lambda x: objective(scale, 0.0, x)) if creep_seen else 0.0
    slip = golden(lambda x: objective(scale, x, creep), 0.0, SLIP_MAX, 9)
    scale = golden(lambda x: objective(x, slip, creep), scale * 0.9, scale * 1.1, 6)
    creep = _creep(lambda x: objective(scale, slip, x)) if creep_seen else 0.0
    scale, slip, creep = _simplest(objective, round(scale, 4), round(slip, 4), round(creep, 3))
    effect = fx.ActuatorTurnError(scale, slip, creep=creep)
    return Candidate(name, effect, _note(ratio, flagged, effect))


def _creep(f) -> float:
    return golden(f, 0.0, CREEP_MAX, 7)


def _simplest(objective, scale: float, slip: float, creep: float) -> tuple:
    """The fitted parameters, with each of scale 1, slip 0, creep 0 taken instead where
    the objective stays within ``SAME`` of the fitted one (fewer departures from the
    simulator for the same fit)."""
    best = objective(scale, slip, creep)
    out = [scale, slip, creep]
    for i, plain in ((0, 1.0), (1, 0.0), (2, 0.0)):
        if out[i] == plain:
            continue
        trial = list(out)
        trial[i] = plain
        if objective(*trial) <= best + SAME * abs(best):
            out = trial
    return tuple(out)


def _note(ratio: float, flagged: dict, effect) -> str:
    note = f'turn response {ratio:.2f} times the simulated'
    scatter = [k.part for f in SCATTER for k in flagged[f]]
    if scatter:
        note += f'; turns scatter more than simulated ({", ".join(sorted(set(scatter)))})'
    return f'{note}: scale {effect.scale:g}, slip {effect.slip:g}, creep {effect.creep:g} deg'
