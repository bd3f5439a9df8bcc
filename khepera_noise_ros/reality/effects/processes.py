"""The physical processes between the light a sensor receives and the integer it reports."""
from __future__ import annotations

import numpy as np
from scipy.special import ndtr

from ...core.khepera import DARK, SENSORS
from .config import (DRIFT_DRAWS, FLICKER_DRAW, GROUP_DRAWS, SENSOR_DRAWS, ActuatorTurnError,
                     CorrelatedNoise, EffectsConfig, IntensityDependentNoise,
                     SaturationQuantization, SensorGainOffset, SensorLatency, TemporalDrift)


# --- the processes ---------------------------------------------------------------------

def _mask(location) -> np.ndarray:
    mask = np.zeros(SENSORS, bool)
    mask[list(location)] = True
    return mask


class Calibration:
    """sensor_gain_offset: fixed per robot and sensor."""

    def __init__(self, effect: SensorGainOffset, robots: int):
        units = range(robots) if effect.per_robot else [None] * robots
        draws = np.stack([np.random.default_rng(
            [effect.unit_seed] if r is None else [effect.unit_seed, r]).standard_normal(
            (2, SENSORS)) for r in units], axis=1)          # (2, robots, 8)
        gains = 1.0 + effect.strength * draws[0]
        offsets = effect.offset_sd * draws[1]
        if effect.gains is not None:
            gains[:] = effect.gains
        if effect.offsets is not None:
            offsets[:] = effect.offsets
        mask = _mask(effect.location)
        self.gains = np.where(mask, gains, 1.0)
        self.offsets = np.where(mask, offsets, 0.0)

    def apply(self, level, z, rows):
        return DARK - self.gains[rows] * (DARK - level) + self.offsets[rows]


class Drift:
    """temporal_drift: r * (1 + d), d an AR(1) process started at its stationary spread."""

    def __init__(self, effect: TemporalDrift, robots: int, start: np.ndarray):
        self.effect = effect
        self.a = float(np.exp(-1.0 / effect.time_constant))
        self.mask = _mask(effect.location)
        self.state = effect.strength * self._shape(start)            # (robots, 8)

    def _shape(self, z):
        return np.repeat(z[:, :1], SENSORS, axis=1) if self.effect.shared else z

    def apply(self, level, z, rows):
        innovation = self._shape(z[:, DRIFT_DRAWS])
        self.state[rows] = self.a * self.state[rows] + \
            np.sqrt(1.0 - self.a ** 2) * self.effect.strength * innovation
        return np.where(self.mask, level * (1.0 + self.state[rows]), level)


class Flicker:
    """intensity_dependent_noise: one flicker draw, amplitude growing with darkness."""

    def __init__(self, effect: IntensityDependentNoise):
        self.effect = effect
        self.mask = _mask(effect.location)

    def apply(self, level, z, rows):
        dark = np.clip(level, 0.0, None) / DARK
        swing = self.effect.strength * level * dark ** self.effect.exponent
        return np.where(self.mask, level + z[:, FLICKER_DRAW:FLICKER_DRAW + 1] * swing, level)


class GroupNoise:
    """correlated_noise: one draw per group, scaled by the group's mean reading."""

    def __init__(self, effect: CorrelatedNoise):
        self.effect = effect

    def apply(self, level, z, rows):
        out = level.copy()
        for g, members in enumerate(self.effect.location):
            members = list(members)
            mean = level[:, members].mean(axis=1, keepdims=True)
            out[:, members] += self.effect.strength * mean * z[:, GROUP_DRAWS][:, g:g + 1]
        return out


class SensorNoise:
    """Each sensor's own noise, uniform in +-p * reading."""

    def __init__(self, level: float):
        self.level = level

    def apply(self, level, z, rows):
        u = ndtr(z[:, SENSOR_DRAWS])
        return level + (2.0 * u - 1.0) * self.level * level


class Latency:
    """sensor_latency: a ring of past measurements per robot."""

    def __init__(self, effect: SensorLatency, robots: int):
        self.delay = effect.strength
        self.mask = _mask(effect.location)
        self.ring = np.full((robots, self.delay + 1, SENSORS), np.nan)
        self.count = np.zeros(robots, np.int64)

    def apply(self, level, z, rows):
        slot = self.count[rows] % (self.delay + 1)
        first = self.count[rows] == 0
        self.ring[rows[first]] = level[first][:, None, :]      # fill the past with the first
        self.ring[rows, slot] = level
        past = self.ring[rows, (self.count[rows] + 1) % (self.delay + 1)]
        self.count[rows] += 1
        return np.where(self.mask, past, level)


class Smear:
    """sensor_latency's fraction: the light a measurement integrates while the last turn
    ends, a mix of the light before the turn and after it (a stationary robot: no change)."""

    def __init__(self, effect: SensorLatency, robots: int):
        self.fraction = effect.fraction
        self.mask = _mask(effect.location)
        self.last = np.full((robots, SENSORS), np.nan)

    def apply(self, level, z, rows):
        last = self.last[rows]
        last = np.where(np.isnan(last), level, last)
        self.last[rows] = level
        mixed = self.fraction * last + (1.0 - self.fraction) * level
        return np.where(self.mask, mixed, level)

    def placed(self, rows) -> None:
        """A robot placed by hand is still when it is next read: nothing to mix."""
        self.last[rows] = np.nan


class Converter:
    """saturation_quantization: round to the converter's step, then saturate."""

    def __init__(self, effect: SaturationQuantization):
        self.effect = effect
        self.mask = _mask(effect.location)

    def apply(self, level, z, rows):
        e = self.effect
        coarse = np.clip(np.round(level / e.strength) * e.strength, e.low, e.high)
        return np.where(self.mask, coarse, level)


class SensorChain:
    """The processes between the light a sensor receives and the integer it reports."""

    def __init__(self, config: EffectsConfig, robots: int, start: np.ndarray):
        c = config
        chain = []
        if c.sensor_latency.enabled and c.sensor_latency.fraction > 0:
            chain.append(Smear(c.sensor_latency, robots))
        if c.sensor_gain_offset.enabled:
            chain.append(Calibration(c.sensor_gain_offset, robots))
        if c.temporal_drift.enabled:
            chain.append(Drift(c.temporal_drift, robots, start))
        if c.intensity_dependent_noise.enabled:
            chain.append(Flicker(c.intensity_dependent_noise))
        if c.correlated_noise.enabled:
            chain.append(GroupNoise(c.correlated_noise))
        if c.sensor_noise > 0:
            chain.append(SensorNoise(c.sensor_noise))
        if c.sensor_latency.enabled and c.sensor_latency.strength > 0:
            chain.append(Latency(c.sensor_latency, robots))
        if c.saturation_quantization.enabled:
            chain.append(Converter(c.saturation_quantization))
        self.chain = chain

    def placed(self, rows) -> None:
        """The experimenter has placed these robots (processes that care forget the turn)."""
        for process in self.chain:
            if hasattr(process, 'placed'):
                process.placed(rows)

    def measure(self, light: np.ndarray, z: np.ndarray, rows) -> np.ndarray:
        """(n, 8) integer readings 0..525 from ideal readings ``light`` (n, 8) and draws
        ``z`` (n, DRAWS) of the robots ``rows``."""
        level = np.asarray(light, np.float64)
        for process in self.chain:
            level = process.apply(level, z, rows)
        return np.clip(np.rint(level), 0, DARK).astype(np.int64)


def turn_error(effect: ActuatorTurnError, deg, z) -> np.ndarray:
    """The rotation a commanded turn of ``deg`` degrees actually produces."""
    deg = np.asarray(deg, np.float64)
    if not effect.enabled:
        return deg
    deg = np.sign(deg) * np.maximum(np.abs(deg) - effect.dead_band, 0.0)
    sided = np.where(deg > 0, 1.0 + effect.asymmetry, 1.0 - effect.asymmetry)
    return deg * effect.scale * sided + effect.strength * np.abs(deg) * z
