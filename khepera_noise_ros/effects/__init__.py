"""Simulator-side models of the unmodelled effects, one module per effect, one registry.

Pure numpy (no ROS, no diagnosis): the simulator node runs fitted effects from here,
and the diagnosis (``gap``) fits them.  An effect is registered by adding its class to
``REGISTRY``; the vocabulary is the registered names the diagnosis looks for.  Effects
travel as a JSON list (``dumps``/``loads``): the simulator's ``effects`` parameter and
``fitted_params.yaml``.
"""
from __future__ import annotations

import json
from typing import Any, Iterable

from .actuator_response import ActuatorResponse
from .actuator_turn_error import ActuatorTurnError
from .base import Effect, Param, Stage
from .correlated_noise import CorrelatedNoise
from .empirical_noise import EmpiricalNoise
from .intensity_dependent_noise import IntensityDependentNoise
from .light_response import LightResponse
from .saturation_quantization import SaturationQuantization
from .sensor_gain_offset import SensorGainOffset
from .sensor_latency import SensorLatency
from .sensor_response import SensorResponse
from .temporal_drift import TemporalDrift

REGISTRY: dict[str, type[Effect]] = {cls.name: cls for cls in (
    CorrelatedNoise, IntensityDependentNoise, SensorGainOffset, TemporalDrift,
    ActuatorTurnError, SensorLatency, SaturationQuantization, EmpiricalNoise,
    LightResponse, ActuatorResponse, SensorResponse)}
# the world model's parts the diagnosis identifies beside the unmodelled effects
WORLD_MODEL = (LightResponse.name, ActuatorResponse.name, SensorResponse.name)
# the unmodelled effects (the emulated robot's vocabulary); the empirical remainder is
# fitted to what the chosen effects leave
NAMES = tuple(n for n in REGISTRY if n not in (EmpiricalNoise.name,) + WORLD_MODEL)
VOCABULARY = NAMES + ('none',)
DEFAULT = NAMES + WORLD_MODEL         # what the diagnosis looks for unless told

__all__ = ['REGISTRY', 'NAMES', 'VOCABULARY', 'WORLD_MODEL', 'DEFAULT', 'Effect', 'Param',
           'Stage', 'from_dict', 'dumps', 'loads', 'ActuatorResponse', 'ActuatorTurnError',
           'CorrelatedNoise', 'EmpiricalNoise', 'IntensityDependentNoise', 'LightResponse',
           'SaturationQuantization', 'SensorGainOffset', 'SensorLatency', 'SensorResponse',
           'TemporalDrift']


def from_dict(data: Any) -> Effect:
    """An effect from its dict form; a ValueError names what is wrong."""
    if not isinstance(data, dict) or data.get('name') not in REGISTRY:
        raise ValueError(f'an effect needs a name from {list(REGISTRY)}, got {data!r}')
    try:
        return REGISTRY[data['name']].from_fields(data)
    except TypeError as exc:       # a field the dataclass cannot take
        raise ValueError(f'effect {data["name"]}: {exc}') from None


def dumps(effects: Iterable[Effect]) -> str:
    """The simulator's ``effects`` parameter: a JSON list ('' for none)."""
    effects = list(effects)
    return json.dumps([e.to_dict() for e in effects]) if effects else ''


def loads(text: str) -> tuple[Effect, ...]:
    """The effects of a JSON list; a ValueError names what is wrong."""
    if not text.strip():
        return ()
    try:
        data = json.loads(text)
        if not isinstance(data, list):
            raise ValueError(f'effects must be a JSON list, got {type(data).__name__}')
        return tuple(from_dict(d) for d in data)
    except json.JSONDecodeError as exc:
        raise ValueError(f'effects must be a JSON list of effects, got {text[:60]!r} '
                         f'({exc.msg})') from None
    except RecursionError:
        raise ValueError('effects: JSON nested too deeply') from None
