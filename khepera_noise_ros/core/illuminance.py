"""Light readings as illuminance, and their variance under a noise model.

A Khepera reading is a count from 0 (brightest) to 525 (darkest), not lux.
``illuminance`` turns it the way round a light meter reads: ``lux_per_count *
(525 - reading)``; with the default of 1 that is "counts of brightness", and a
user with a light meter sets ``lux_per_count`` to calibrate it.

``reading_variance`` is the model's variance at a reading: the sensor's own
independent draw, the shared draw of its dependence group (combination model),
and a twelfth of a count, the resolution of a whole-count reading.  A draw of
level p on a value v spreads as p v / sqrt(3) and is truncated to whole counts
(``draw_variance``).  The value is the reading itself and a group's average the
average of its readings: the noiseless base is not known.  Clipping at 0 and
525 is left out, so near those ends the true spread is smaller.
"""
from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .khepera import DARK, SENSORS
from .noise import NoiseModel

QUANTISATION = 1.0 / 12.0       # variance of rounding to a whole count


def illuminance(readings: npt.ArrayLike, lux_per_count: float = 1.0) -> np.ndarray:
    """Readings (counts, 0 brightest) to illuminance, brighter is larger."""
    return lux_per_count * (DARK - np.asarray(readings, np.float64))


def draw_variance(half_width: npt.ArrayLike, distribution: str) -> np.ndarray:
    """Variance of ``getnoise``: a draw of half-width a = p v (uniform on +-a, or normal
    of the same spread) truncated toward zero.  Exact for the uniform draw; for the
    normal one sigma^2 - E|x| + 1/6, exact in the limit of a large sigma."""
    a = np.abs(np.asarray(half_width, np.float64))
    if distribution == 'uniform':
        n = np.floor(a)
        with np.errstate(invalid='ignore', divide='ignore'):
            exact = ((n - 1) * n * (2 * n - 1) / 6 + (a - n) * n * n) / a
        return np.where(a > 0, exact, 0.0)
    sigma = a / np.sqrt(3.0)
    return np.where(a > 0, np.maximum(sigma ** 2 - sigma * np.sqrt(2 / np.pi) + 1 / 6, 0.0),
                    0.0)


def reading_variance(readings: npt.ArrayLike, noise: NoiseModel) -> np.ndarray:
    """(SENSORS,) variance in counts^2 of the eight readings of one robot."""
    v = np.asarray(readings, np.float64).reshape(SENSORS)
    dependent, independent = noise.levels
    variance = draw_variance(independent * v, noise.distribution) + QUANTISATION
    if dependent > 0:
        for group in noise.groups:
            members = list(group)
            variance[members] += draw_variance(dependent * v[members].mean(),
                                               noise.distribution)
    return variance


def illuminance_variance(readings: npt.ArrayLike, noise: NoiseModel | None,
                         lux_per_count: float = 1.0) -> np.ndarray:
    """(SENSORS,) variance of ``illuminance``; zeros (unknown) without a noise model."""
    if noise is None:
        return np.zeros(SENSORS)
    return lux_per_count ** 2 * reading_variance(readings, noise)
