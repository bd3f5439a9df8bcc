"""The simulator's configuration as the gap tools see it: a params YAML, read and written.

The file is the one the simulator node loads with ``--ros-args --params-file``:
``{node: {ros__parameters: {...}}}`` with the node's parameter names
(``noise_model``, ``dependent_level``, ``independent_level``,
``dependence_groups`` as '0,1,2;3,4,5', ``distribution``, ``rounding``, ``seed``, the world's
geometry, ``steps``, ``perturb_every``, ``perturbation_deg``) and ``effects``, a
JSON list of the unmodelled effects the simulator should add (see
``khepera_noise_ros.effects``).  Keys the file does not give keep the simulator's defaults.
This module imports no ROS, so a recording can be diagnosed without it.
"""
from __future__ import annotations

import dataclasses
import difflib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping

import yaml

from .core.khepera import WORLD_KEYS, World
from .core.noise import NoiseModel, format_groups, parse_groups
from .core.task import Task
from .files import StrPath, atomic_write_text
from . import effects as fx

TASK_KEYS = ('steps', 'perturb_every', 'perturbation_deg')
NOISE_KEYS = ('noise_model', 'dependent_level', 'independent_level', 'dependence_groups',
              'distribution', 'rounding')
KNOWN = WORLD_KEYS + TASK_KEYS + NOISE_KEYS + ('seed', 'effects')


@dataclass(frozen=True)
class SimConfig:
    world: World = field(default_factory=World)
    noise: NoiseModel = field(default_factory=NoiseModel)
    task: Task = field(default_factory=Task)
    seed: int = 0
    effects: tuple[fx.Effect, ...] = ()

    def with_effects(self, *added: fx.Effect) -> 'SimConfig':
        return dataclasses.replace(self, effects=tuple(self.effects) + tuple(added))

    def parameters(self) -> dict[str, Any]:
        """The node parameters that reproduce this configuration."""
        n = self.noise
        values: dict[str, Any] = {
            'noise_model': n.model, 'dependent_level': float(n.dependent),
            'independent_level': float(n.independent),
            'dependence_groups': format_groups(n.groups), 'distribution': n.distribution,
            'rounding': n.rounding}
        values.update({k: float(getattr(self.world, k)) for k in WORLD_KEYS})
        values.update({'steps': self.task.steps, 'perturb_every': self.task.perturb_every,
                       'perturbation_deg': float(self.task.perturbation_deg),
                       'effects': fx.dumps(self.effects)})
        return values


def from_parameters(values: Mapping[str, Any], source: str = 'parameters') -> SimConfig:
    """A SimConfig from node parameter values; errors name the file and the key.

    Other parameters of the node (mode, rate_hz, robots, ...) are ignored, but a name
    that is a near miss of one of ours is refused as a likely typo.
    """
    for key in values:
        close = difflib.get_close_matches(key, KNOWN, n=1, cutoff=0.8)
        if key not in KNOWN and close:
            raise ValueError(f'{source}: unknown simulator parameter {key!r}; did you mean '
                             f'{close[0]!r}?')
    values = {k: v for k, v in values.items() if k in KNOWN}
    base = SimConfig()
    try:
        world = dataclasses.replace(base.world, **{k: float(values[k]) for k in WORLD_KEYS
                                                   if k in values})
        task = dataclasses.replace(base.task, **{k: values[k] for k in TASK_KEYS
                                                 if k in values})
        n = base.noise
        groups = values.get('dependence_groups', format_groups(n.groups))
        noise = NoiseModel(model=values.get('noise_model', n.model),
                           dependent=float(values.get('dependent_level', n.dependent)),
                           independent=float(values.get('independent_level', n.independent)),
                           groups=parse_groups(groups) if isinstance(groups, str) else groups,
                           distribution=values.get('distribution', n.distribution),
                           rounding=values.get('rounding', n.rounding))
        text = values.get('effects', '') or ''
        if not isinstance(text, str):       # a number or a list would fail inside loads
            raise ValueError(f'effects must be a string of effects, got {text!r}')
        effects = fx.loads(text)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'{source}: {exc}') from None
    seed = values.get('seed', 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f'{source}: seed must be an integer >= 0, got {seed!r}')
    return SimConfig(world, noise, task, seed, effects)


def load(path: StrPath | None = None) -> SimConfig:
    """The configuration in a params YAML; the simulator's defaults for None."""
    if path is None:
        return SimConfig()
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f'{path}: no such params file')
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ValueError(f'{path}: not valid YAML: {" ".join(str(exc).split())}') from None
    return from_parameters(_node_parameters(data, path), str(path))


def _node_parameters(data: object, path: Path) -> dict[str, Any]:
    """The ros__parameters of the file's node sections, merged (a flat mapping is accepted)."""
    if not isinstance(data, dict):
        raise ValueError(f'{path}: expected {{node: {{ros__parameters: {{...}}}}}}, '
                         f'got {type(data).__name__}')
    sections = [v['ros__parameters'] for v in data.values()
                if isinstance(v, dict) and isinstance(v.get('ros__parameters'), dict)]
    if not sections:
        if any(k in KNOWN for k in data):
            return data
        raise ValueError(f'{path}: no node section with ros__parameters found')
    merged: dict[str, Any] = {}
    for section in sections:
        merged.update(section)
    return merged


def dump(config: SimConfig, node: str = '/**', keys: Iterable[str] | None = None) -> str:
    """Params YAML text for ``node``; ``keys`` limits it to some parameters."""
    values = config.parameters()
    if keys is not None:
        values = {k: values[k] for k in keys}
    return yaml.safe_dump({node: {'ros__parameters': values}}, sort_keys=False)


def write(config: SimConfig, path: StrPath, keys: Iterable[str] | None = None,
          header: str = '') -> Path:
    text = ''.join(f'# {line}\n' for line in header.splitlines()) + dump(config, keys=keys)
    return atomic_write_text(path, text)
