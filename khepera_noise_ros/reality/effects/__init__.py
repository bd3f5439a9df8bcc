"""The unmodelled effects of the emulated robot, each a physical process of its own.

The simulator perturbs an ideal reading with the paper's noise model.  A real
Khepera's readings come out of a chain of physical processes instead; the
emulator runs that chain, in this order, on the light each sensor receives:

  (sensor_latency)           a measurement integrates its light over a window that
                             overlaps the end of the last turn (``fraction``)
  sensor_gain_offset         each sensor's own gain on the light and dark offset
                             (a fixed calibration of the unit)
  temporal_drift             slow AR(1) wander of the gain (warm-up, supply, daylight)
  intensity_dependent_noise  the room's light flicker, seen by all sensors at once and
                             stronger when they read darker
  correlated_noise           white noise shared within each group of adjacent sensors
                             (a common supply/reference per group)
  sensor noise               each sensor's own noise, uniform +-``sensor_noise`` of the
                             reading: the paper's independent noise, always on
  sensor_latency             a sensor reports what it measured ``strength`` samples ago
  saturation_quantization    clipping and coarse quantisation of the converter
and, on the wheels, ``actuator_turn_error``: a turn's rotation differs from the
one commanded by a dead band (static friction), a scale (wheel slip on the floor),
unequal motors (``asymmetry``) and a random part.

Every effect has ``enabled`` and ``strength`` and, where it makes sense, a
``location`` (sensors, or groups of sensors); the names are those the gap
diagnosis uses.  ``EffectsConfig`` (``config``) is loaded from and saved to YAML; a
bad value is a ValueError naming its key; ``processes`` carries the effects out.
Randomness arrives as a fixed block of standard normal draws per robot and
sample (``DRAWS``), so switching an effect on or off never changes the draws
another effect sees.
"""
from .config import (ALL_SENSORS, BASES, DRAWS, EFFECT_TYPES, EFFECTS, FORMAT, REAL_ROBOT,
                     REAL_ROBOT_V1, ActuatorTurnError, CorrelatedNoise, EffectsConfig,
                     IntensityDependentNoise, SaturationQuantization, SensorGainOffset,
                     SensorLatency, TemporalDrift)
from .processes import SensorChain, turn_error

__all__ = ['ALL_SENSORS', 'BASES', 'DRAWS', 'EFFECT_TYPES', 'EFFECTS', 'FORMAT', 'REAL_ROBOT',
           'REAL_ROBOT_V1', 'ActuatorTurnError', 'CorrelatedNoise', 'EffectsConfig',
           'IntensityDependentNoise', 'SaturationQuantization', 'SensorGainOffset',
           'SensorLatency', 'TemporalDrift', 'SensorChain', 'turn_error']
