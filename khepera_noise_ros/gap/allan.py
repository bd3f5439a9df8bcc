"""Allan deviation of the run residuals, per sensor and shared: white noise falls as
tau^-1/2, a wander grows (docs/diagnosis.md, "Allan deviation")."""
from __future__ import annotations

from typing import Any, Iterable, Sequence

import numpy as np

from ..effects.base import Array
from ..recording import Recording
from .protocol import runs as run_indices

SLOPES = {'white': -0.5, 'flicker': 0.0, 'random_walk': 0.5, 'drift': 1.0}


def deviation(series: Iterable[Array], factors: Sequence[int], width: int) -> tuple[Array, Array]:
    """(overlapping Allan deviation (factors, width) of the (N, width) rate series pooled,
    terms per factor): with the phase x = cumsum(y) (a leading 0), sigma^2(m) =
    sum (x[i+2m] - 2 x[i+m] + x[i])^2 / (2 m^2 terms); NaN with no terms."""
    sums, terms = np.zeros((len(factors), width)), np.zeros(len(factors))
    for y in series:
        x = np.vstack([np.zeros((1, width)), np.cumsum(y, axis=0)])
        for i, m in enumerate(factors):
            if y.shape[0] >= 2 * m + 1:
                d = x[2 * m:] - 2.0 * x[m:-m] + x[:-2 * m]
                sums[i] += (d * d).sum(axis=0)
                terms[i] += d.shape[0]
    with np.errstate(invalid='ignore', divide='ignore'):
        adev = np.sqrt(sums / (2.0 * np.square(factors)[:, None] * terms[:, None]))
    return adev, terms


def taus(longest: int) -> list[int]:
    """Averaging factors 1, 2, 4, ... up to a third of the longest run."""
    out, m = [], 1
    while 2 * m + 1 <= max(3, longest) and m <= max(1, longest // 3):
        out.append(m)
        m *= 2
    return out


def profile(rec: Recording, factors: Sequence[int]) -> dict[str, Any]:
    """{'taus': [...], 'sensors': {s: [adev per tau]}, 'shared': [adev per tau]} of the
    recording's run residuals at averaging ``factors``, pooled over runs (stationary only)."""
    used = list(rec.channels_used)
    runs = [r for r in run_indices(rec) if r.size >= 3]

    def residuals(r: np.ndarray) -> Array:
        y = rec.readings[r][:, used].astype(np.float64)
        y = y - y.mean(axis=0)
        return np.concatenate([y, y.mean(axis=1, keepdims=True)], axis=1)
    adev, terms = deviation(map(residuals, runs), factors, len(used) + 1)
    return {'taus': list(factors), 'terms': terms.tolist(),
            'sensors': {int(s): adev[:, k].tolist() for k, s in enumerate(used)},
            'shared': adev[:, -1].tolist()}


def slope(taus_: Sequence[float], adev: Sequence[float]) -> float:
    """Log-log slope of the deviation over its last three averaging times."""
    t, a = np.log(np.asarray(taus_, float)), np.log(np.asarray(adev, float))
    ok = np.isfinite(a)
    t, a = t[ok][-3:], a[ok][-3:]
    if t.size < 2:
        return float('nan')
    return float(np.polyfit(t, a, 1)[0])


def term(value: float) -> str:
    """The noise term whose slope is nearest ``value``."""
    if not np.isfinite(value):
        return 'unknown'
    return min(SLOPES, key=lambda k: abs(SLOPES[k] - value))


def compare(real: dict[str, Any], sim: dict[str, Any]) -> dict[str, Any]:
    """Real against simulated profiles: per sensor and shared, the ratio of deviations at
    the shortest and longest averaging time and the long-tau slope's noise term."""
    out: dict[str, Any] = {'taus': real['taus'], 'real': real, 'simulated': sim, 'sensors': {}}
    sides = [(key, r, sim['sensors'].get(key)) for key, r in real['sensors'].items()]
    for key, r, s in sides + [('shared', real['shared'], sim['shared'])]:
        if s is None or not r:
            continue
        ratio = [float(a / b) if b and np.isfinite(a) and np.isfinite(b) and b > 0 else None
                 for a, b in zip(r, s)]
        row = {'short_ratio': ratio[0], 'long_ratio': ratio[-1],
               'real_term': term(slope(real['taus'], r)),
               'simulated_term': term(slope(real['taus'], s))}
        (out if key == 'shared' else out['sensors'])[key] = row
    return out
