"""Spread laws: how the sd of the extra noise depends on the light level.

A law is  sd(r) = constant + strength * u * (u / scale) ** exponent  with u = r (the
noise grows with darkness, the Khepera's 525 end) or u = scale - r (it grows with
brightness), any exponent in a grid from -0.5 to 4, and a constant part >= 0.  Fitted
to the excess variance of each cell (real spread^2 minus simulated spread^2 at the
cell's level) by non-negative least squares on the sd, every direction and exponent
tried; the best few are then judged by the simulator (``fit.intensity``).
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import nnls

EXPONENTS = (-0.5, 0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0)
DIRECTIONS = ('dark', 'bright')


def shape(level, direction: str, exponent: float, scale: float = 525.0) -> np.ndarray:
    """u * (u / scale) ** exponent, u the distance from the quiet end; 0 where u is 0."""
    r = np.clip(np.asarray(level, np.float64), 0.0, scale)
    u = r if direction == 'dark' else scale - r
    with np.errstate(divide='ignore', invalid='ignore'):
        out = u * (u / scale) ** exponent
    return np.where(u > 0, np.nan_to_num(out, nan=0.0, posinf=0.0), 0.0)


def laws(cells, top: int = 3, scale: float = 525.0) -> list[tuple]:
    """The ``top`` laws (direction, exponent, constant, strength, residual) that fit the
    cells [(level, excess variance), ...] best."""
    if not cells:
        return []
    level = np.array([c[0] for c in cells], np.float64)
    sd = np.sqrt(np.clip(np.array([c[1] for c in cells], np.float64), 0.0, None))
    out = []
    for direction in DIRECTIONS:
        for exponent in EXPONENTS:
            x = np.stack([np.ones_like(level), shape(level, direction, exponent, scale)], axis=1)
            if not np.isfinite(x).all() or x[:, 1].max() <= 0:
                continue
            norm = x.max(axis=0)
            coef, residual = nnls(x / norm, sd)
            coef = coef / norm
            out.append((direction, exponent, float(coef[0]), float(coef[1]), float(residual)))
    out.sort(key=lambda t: t[4])
    return out[:top]


def describe(direction: str, exponent: float, constant: float, strength: float) -> str:
    u = 'r' if direction == 'dark' else '(525 - r)'
    return (f'sd = {constant:.3g} + {strength:.3g} * {u} * ({u} / 525)^{exponent:g} '
            f'(grows with {"darkness" if direction == "dark" else "brightness"})')
