"""Between a foreign robot's light and the integer it reports: dynamics, then noise.

The cells respond gradually (a first-order lag, faster towards bright than towards dark
or the other way round), their values reach the converter late by a fractional number of
samples (interpolated between two samples), the lamp flickers slowly and for all sensors
at once (an AR(1) wander of its light), each cell adds noise that grows with the light it
takes in (shot noise, largest for bright readings), and the converter has a step.
"""
from __future__ import annotations

import numpy as np

from .light import DARK

SHOT_FLOOR = 25.0         # reading units of light below which the shot noise stops falling


class Sensing:
    """The sensors' state of ``robots`` copies of one robot: their lag and their past."""

    def __init__(self, params: dict, robots: int, flicker_start: np.ndarray):
        self.dynamics, self.noise = params['dynamics'], params['noise']
        self.dark = params['light']['dark']
        delay = self.dynamics['delay']
        self._whole, self._part = int(np.floor(delay)), delay - np.floor(delay)
        self.lagged = np.zeros((robots, 8))
        self.past = np.zeros((robots, self._whole + 2, 8))   # lagged values, newest first
        self.flicker = self.noise['flicker'] * flicker_start

    def lamp_gain(self, rows: np.ndarray, z: np.ndarray | None = None) -> np.ndarray:
        """(n,) the lamp's light factor now; with draws ``z`` (n,), after one more sample."""
        if z is not None:
            rho = np.exp(-1.0 / self.noise['flicker_samples'])
            self.flicker[rows] = rho * self.flicker[rows] + \
                np.sqrt(1.0 - rho * rho) * self.noise['flicker'] * z
        return np.maximum(1.0 + self.flicker[rows], 0.0)

    def settle(self, rows: np.ndarray, clean: np.ndarray) -> None:
        """The robot has stood still a while (it was just placed): no lag, no past."""
        self.lagged[rows] = clean
        self.past[rows] = clean[:, None, :]

    def measure(self, rows: np.ndarray, clean: np.ndarray, z: np.ndarray) -> np.ndarray:
        """(n, 8) integer readings of one sample from the cells' analogue values ``clean``.

        Args:
            z: (n, 8) standard normals for the shot noise.
        """
        lagged = self.lagged[rows]
        rate = np.where(clean < lagged, self.dynamics['brighten'], self.dynamics['darken'])
        lagged += rate * (clean - lagged)
        self.lagged[rows] = lagged
        past = np.roll(self.past[rows], 1, axis=1)
        past[:, 0] = lagged
        self.past[rows] = past
        late = (1.0 - self._part) * past[:, self._whole] + self._part * past[:, self._whole + 1]
        spread = self.noise['shot'] * np.sqrt(np.maximum(self.dark - late, 0.0) + SHOT_FLOOR)
        step = self.noise['step']
        return np.clip(np.rint((late + spread * z) / step) * step, 0.0, DARK)
