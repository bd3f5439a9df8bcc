"""``actuator_turn_error``: a commanded turn rotates the robot by a different amount.

The fit: the readings' response to a turn scaled (``turn_response``,
``sensor_turn_response``), the turn itself where headings are recorded (``turn_size``),
and for a random error, which leaves those alone, the scatter of the turn by band of
power (``turn_scatter``, ``turn_size_scatter``).  Scale, slip and creep (only where power
0 scatters) by golden-section search in turn; a plain value is kept where it fits as well.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .base import Array, Candidate, Effect, Evidence, Stage, param
from .fitting import CLOSED_LOOP, Z_DETECT, golden

SCATTER = ('turn_scatter', 'turn_size_scatter')
FAMILIES = ('turn_response', 'sensor_turn_response', 'turn_size') + SCATTER
STILL = 'power 0'         # the scatter band where only a creep can act
SLIP_MAX = 0.8            # sd of the slip per degree turned searched over
CREEP_MAX = 10.0          # degrees per step searched over
SAME = 0.02               # relative objective within which the simpler value is kept


@dataclass(frozen=True)
class ActuatorTurnError(Effect, name='actuator_turn_error', stage=Stage.ACTUATOR, free=2,
                        summary='a turn command produces a different rotation than modelled'):
    """A commanded rotation of x degrees turns x * scale + slip * |x| * N(0, 1) + creep *
    N(0, 1) degrees (the creep turns the robot even at power 0).  With ``knocks`` the
    task's heading knocks are scaled too: on a robot the wheels make them."""

    scale: float = param(1.0, 'executed over commanded rotation')
    slip: float = param(0.0, 'sd of a random slip per degree turned', low=0.0)
    knocks: bool = param(True, 'the task\'s heading knocks are scaled too')
    creep: float = param(0.0, 'sd of a slip of fixed size, degrees per step', low=0.0)

    def act(self, level: Array, rng: np.random.Generator) -> Array:
        # the creep drawn only when set: older effects keep their streams
        draws = rng.standard_normal((level.shape[0], 2 if self.creep else 1) + level.shape[2:])
        out = level * self.scale + self.slip * np.abs(level) * draws[:, :1]
        if self.creep:
            out = out + self.creep * draws[:, 1:]
        return out

    @classmethod
    def fit(cls, evidence: Evidence) -> Candidate:
        response = [r for r in evidence.rows('turn_response') if r.key.part == 'lag 0']
        if not response:
            return cls.nothing('no closed-loop data: turns cannot be checked')
        # a random error only adds scatter: less than simulated is no fingerprint of it
        flagged = {f: [r.key for r in evidence.rows(f)
                       if (r.z if f in SCATTER else abs(r.z)) > Z_DETECT] for f in FAMILIES}
        if not any(flagged.values()):
            return cls.nothing('the readings respond to turns as simulated')
        # recorded headings measure the turn itself; else the readings' response to it, at
        # both lags (least squares): with a latency given, the lag-0 response is noise alone
        measured = evidence.rows('turn_size') or evidence.rows('turn_response')
        pairs = np.array([(r.real, r.sim) for r in measured], np.float64)
        real, sim = pairs[np.isfinite(pairs).all(axis=1)].T
        ratio = float(real @ sim / (sim @ sim)) if sim @ sim > 1e-18 else 1.0
        scale0 = float(np.clip(ratio, 0.2, 2.0))
        creeps = any(k.part == STILL for f in SCATTER for k in flagged[f])
        # beside a latency, not the change residuals: what the latency leaves there pulls
        # the scale the wrong way
        present = evidence.families()
        change = frozenset(f for f in present if f.startswith('loop_change_'))
        lagged = any(e.name == 'sensor_latency' for e in evidence.given)
        families = present - change if lagged and change else None

        def objective(scale: float, slip: float, creep: float = 0.0) -> float:
            return evidence.objective([cls(scale, slip, creep=creep)], (CLOSED_LOOP,), families)
        # the creep first where power 0 shows it (there the slip cannot act), then the
        # slip given it, the scale once more, and the creep given both
        scale = golden(lambda x: objective(x, 0.0), scale0 * 0.7, scale0 * 1.45, 8)
        creep = golden(lambda x: objective(scale, 0.0, x), 0.0, CREEP_MAX, 7) if creeps else 0.0
        slip = golden(lambda x: objective(scale, x, creep), 0.0, SLIP_MAX, 9)
        scale = golden(lambda x: objective(x, slip, creep), scale * 0.9, scale * 1.1, 6)
        creep = golden(lambda x: objective(scale, slip, x), 0.0, CREEP_MAX, 7) if creeps else 0.0
        scale, slip, creep = _simplest(objective, round(scale, 4), round(slip, 4), round(creep, 3))
        effect = cls(scale, slip, creep=creep)
        note = f'turn response {ratio:.2f} times the simulated'
        scatter = sorted({str(k.part) for f in SCATTER for k in flagged[f]})
        if scatter:
            note += f'; turns scatter more than simulated ({", ".join(scatter)})'
        return Candidate(cls.name, effect, f'{note}: scale {effect.scale:g}, slip '
                                           f'{effect.slip:g}, creep {effect.creep:g} deg')


def _simplest(objective: Callable[..., float], scale: float, slip: float,
              creep: float) -> tuple[float, float, float]:
    """The fitted parameters, with scale 1, slip 0 or creep 0 taken instead where the
    objective stays within ``SAME`` of the fitted one."""
    best = objective(scale, slip, creep)
    out = [scale, slip, creep]
    for i, plain in enumerate((1.0, 0.0, 0.0)):
        trial = out[:i] + [plain] + out[i + 1:]
        if out[i] != plain and objective(*trial) <= best + SAME * abs(best):
            out = trial
    return out[0], out[1], out[2]
