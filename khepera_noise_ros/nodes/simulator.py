"""The simulator node: a RobotNode whose robots are the core's simulated Kheperas.

Noise and lamp geometry can be changed while it runs (``ros2 param set`` or a
SetParameters request from another node): the new world and noise model are
swapped into the running episodes and apply from the next step; the task
(steps, perturbations) from the next episode.  A value the core refuses is
refused with its reason and the old value stays.

``effects`` adds unmodelled effects (``khepera_noise_ros.effects``, as ``khepera-noise
diagnose`` fits them) to the robots, through ``effects.simulate.EffectEpisodes``;
with none the episodes are exactly the core's.  A change applies from the next
episode.
"""
from __future__ import annotations

import sys
from typing import Any

from ..core.noise import (DEFAULT_GROUPS, DISTRIBUTIONS, MODELS, ROUNDINGS, NoiseModel,
                          format_groups)
from ..core.task import Task
from .. import effects as fx
from ..effects.simulate import EffectEpisodes
from .runtime import spin_node
from .params import GEOMETRY, SEED_MAX, Spec, noise_from, task_from, world_from
from .robot_node import RobotNode

NOISE = ('noise_model', 'dependent_level', 'independent_level', 'dependence_groups',
         'distribution', 'rounding')
_NOISE = NoiseModel()

SIMULATOR_SPECS = (
    Spec('noise_model', _NOISE.model, 'Sensor noise: independent (one draw per sensor), '
         'combination (plus one shared draw per dependence group) or none.', choices=MODELS),
    Spec('dependent_level', _NOISE.dependent, 'Dependent noise d as a fraction of the group '
         'average (0.03 = 3%); combination model only.', 0.0, 1.0),
    Spec('independent_level', _NOISE.independent, 'Independent noise i as a fraction of each '
         'reading (0.02 = 2%).', 0.0, 1.0),
    Spec('dependence_groups', format_groups(DEFAULT_GROUPS), "Sensors that share dependent "
         "noise: ',' within a group, ';' between groups, sensors 0..7, e.g. '0,1,2,3,4,5;6,7'."),
    Spec('distribution', _NOISE.distribution, 'Shape of every noise draw; normal has the '
         'same standard deviation as uniform.', choices=DISTRIBUTIONS),
    Spec('rounding', _NOISE.rounding, 'Where the reading becomes an integer: level (the '
         "paper's: integer noise on the rounded light level) or reading (the noise added to "
         'the unrounded light level, rounded and clipped once at the end, as a converter '
         'does).', choices=ROUNDINGS),
    Spec('seed', 0, 'Seed of real-time episodes (episode n uses seed + n); lockstep episodes '
         'take their per-robot seeds from episode_start.', 0, SEED_MAX),
    Spec('robots', 1, 'Robots simulated in real-time mode (lockstep: as many as '
         'episode_start names).', 1, 1000000),
    Spec('deg_per_power', 3.0, 'Rotation of one step at power 1, degrees, a multiple of 0.1 '
         '(power 9 turns 9 times as far).', 0.1, 40.0),
)
EFFECTS = Spec('effects', '', 'Unmodelled effects: a JSON list as khepera-noise diagnose '
               'writes it; empty for none.')


def effects_from(values: dict[str, Any]) -> tuple:
    """The effects of the ``effects`` value, tried on one robot for two steps, so that a
    value that parses but cannot run (a sensor beyond 7, a field of the wrong type) is
    refused here rather than failing episodes; a ValueError names the problem."""
    text = values['effects']
    try:
        effects = fx.loads(text)
        trial = EffectEpisodes(world_from(values), noise_from(values), Task(steps=2), effects)
        trial.reset(0, 1)
        trial.step([1], [1])
    except Exception as exc:                # a foreign JSON document can raise anything
        raise ValueError(f'effects: {exc}' if isinstance(exc, ValueError) else
                         f'effects {text[:80]!r} cannot be used: {exc!r}') from None
    return effects


class Simulator(RobotNode):
    """K simulated robots; see RobotNode for the protocol."""

    EXTRA_SPECS = SIMULATOR_SPECS + (EFFECTS,)

    def __init__(self, node_name: str = 'simulator', **kwargs):
        super().__init__(node_name, **kwargs)

    def make_backend(self, values: dict[str, Any]) -> EffectEpisodes:
        return EffectEpisodes(world_from(values), noise_from(values), task_from(values),
                              fx.loads(values['effects']))

    def check_parameters(self, values: dict[str, Any]) -> None:
        super().check_parameters(values)
        noise_from(values)
        effects_from(values)

    def apply_parameters(self, values: dict[str, Any], changed: set[str]) -> None:
        super().apply_parameters(values, changed)
        if changed & (set(GEOMETRY) | {'deg_per_power'}):
            self.backend.world = world_from(values)
        if changed & set(NOISE):
            self.backend.noise = noise_from(values)
        if 'effects' in changed:
            self.backend.effects = fx.loads(values['effects'])

    def realtime_episode(self, count: int) -> tuple[int, int]:
        return (self.values['seed'] + count) % (SEED_MAX + 1), self.values['robots']

    def reading_noise(self) -> NoiseModel:
        """The model's noise (the variance leaves the effects out)."""
        noise = self.backend.noise
        return getattr(noise, 'model_noise', noise)


def main(args=None) -> int:
    return spin_node(Simulator, args)


if __name__ == '__main__':
    sys.exit(main())
