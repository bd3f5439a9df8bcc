"""Settings of the replication: every number of section 4 and the appendix, in one place.

The defaults are the paper's numbers with the measurement protocol that can detect its
effect (``protocol: measured``: ten test episodes, bests chosen by re-test, episodes
from a reset bearing); ``PROTOCOLS['paper']`` is the paper's literal protocol. The
world's unstated parameters are calibrated (docs/calibration.md). A YAML file
(``config/replicate.yaml`` is a commented copy of the defaults) overrides any of them;
keys it does not give keep their default, and an unknown key is an error that names it.
``quick`` holds the overrides ``--quick`` applies on top. The settings actually used are
written next to the results, with a hash that the results store checks on resume.
"""
from __future__ import annotations

import copy
import dataclasses
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import yaml

from ..core.evolution import EAConfig
from ..core.khepera import World
from ..core.noise import DEFAULT_GROUPS, NoiseModel
from ..core.task import Task
from ..reality.effects import EffectsConfig
from . import fitted

FORMAT = 'khepera-noise-replicate-config/1'
MODELS = ('combination', 'independent')     # the compared models, the paper's order
SIMULATION_BACKENDS = ('graph', 'core')
REALITY_BACKENDS = ('emulator', 'world', 'hardware')

DEFAULTS: dict = {
    'protocol': 'measured',
    'seed': 1998,
    'trials': 10,
    'test_episodes': 10,
    'dependence_groups': [list(g) for g in DEFAULT_GROUPS],
    'distribution': 'uniform',
    'levels': [
        {'label': '5%', 'figure': 'fig9',
         'combination': {'dependent': 0.03, 'independent': 0.02}, 'independent': 0.05},
        {'label': '10%', 'figure': 'fig10',
         'combination': {'dependent': 0.05, 'independent': 0.05}, 'independent': 0.10},
    ],
    'phase1': {'population': 25, 'generations': 50, 'init_range': 0.4, 'mutation_range': 1.0,
               'fitness': 'stored', 'best': 'retest', 'retest_episodes': 5},
    'phase2': {'population': 10, 'generations': 5, 'init_range': 0.4, 'mutation_range': 1.0,
               'fitness': 'stored', 'best': 'retest', 'retest_episodes': 5},
    'task': {'steps': 60, 'perturb_every': 5, 'perturbation_deg': 25.0},
    'world': {'lamp_distance_mm': 5.0, 'ambient': 500.0, 'gain': 500.0, 'reach_mm': 250.0,
              'half_angle_deg': 60.0, 'floor': 50.0, 'deg_per_power': 3.0},
    'backend': {'simulation': 'graph', 'reality': 'emulator'},
    # the emulated robot's world: robots in a batch, its seed, and its effects
    # (a mapping for reality.effects.EffectsConfig.from_dict, or the path of such a file)
    # start_bearing_deg: where each real episode starts (null: where the last one ended)
    'reality': {'robots': 100, 'seed': 1, 'effects': {}, 'start_bearing_deg': 0.0},
    # the ceiling arm (--ceiling): phase 2 again from the same phase-1 bests with this budget,
    # and its best tested on the same episodes: how much of the drop real training can
    # recover on this reality at all.  ``enabled`` is not hashed: it adds steps to a run.
    'ceiling': {'enabled': False, 'population': 25, 'generations': 50},
    # the diagnosed condition (--params): null, or a fitted_params.yaml's path or the
    # simulator parameters it holds (its noise and effects; the world and task are these)
    'diagnosed': None,
    'quick': {'trials': 3},
}
# Measurement protocols: overrides laid over the defaults (``measured`` is the defaults).
# ``paper`` is section 4.4 as written: one test episode, the best single evaluation ever
# seen, and a real robot left where its last episode ended.
PROTOCOLS: dict = {
    'measured': {},
    'paper': {'test_episodes': 1, 'phase1': {'best': 'ever'}, 'phase2': {'best': 'ever'},
              'reality': {'start_bearing_deg': None}},
}


@dataclass(frozen=True)
class Condition:
    """One arm of the experiment: a noise level and the model the simulator uses (and, for
    the diagnosed condition, no level and the fitted effects)."""

    level: str            # the level's label, e.g. '5%'; '' for the diagnosed condition
    model: str            # 'combination', 'independent' or 'diagnosed'
    noise: NoiseModel
    effects: tuple = ()   # the simulator's effects (``khepera_noise_ros.effects``)

    @property
    def name(self) -> str:
        """The paper's name, as in Table 1: '5% combination'; 'diagnosed'."""
        return f'{self.level} {self.model}' if self.level else self.model

    @property
    def key(self) -> str:
        """A file-name-safe form of ``name``: '5pct-combination'."""
        if not self.level:
            return self.model
        return f"{self.level.replace('%', 'pct').replace(' ', '_')}-{self.model}"


@dataclass(frozen=True)
class Level:
    label: str
    figure: str
    conditions: tuple[Condition, Condition]   # (combination, independent)


@dataclass(frozen=True)
class ReplicateConfig:
    """Validated settings; ``data`` is the plain form that is written and hashed."""

    data: dict
    seed: int
    trials: int
    test_episodes: int
    levels: tuple[Level, ...]
    phase1: EAConfig
    phase2: EAConfig
    task: Task
    world: World
    reality: dict
    backend: dict
    ceiling: EAConfig | None = None       # phase 2 with the ceiling's budget, when enabled
    diagnosed: Condition | None = None    # the fitted simulator, beside the paper's models

    @property
    def effects(self) -> EffectsConfig:
        """What the emulated reality does beyond the simulator's light response."""
        return EffectsConfig.from_dict(self.reality['effects'])

    @property
    def conditions(self) -> tuple[Condition, ...]:
        """The paper's conditions, level by level, then the diagnosed one if any."""
        return tuple(c for level in self.levels for c in level.conditions) + \
            ((self.diagnosed,) if self.diagnosed is not None else ())

    @property
    def hash(self) -> str:
        """Digest of every setting that changes a result (not the ``quick`` preset, nor
        whether the ceiling arm runs: a run resumed with it keeps its steps 1-5)."""
        data = {**self.data, 'ceiling': {k: v for k, v in self.data['ceiling'].items()
                                         if k != 'enabled'}}
        if data['diagnosed'] is None:       # runs without it keep the hash they had
            del data['diagnosed']
        text = json.dumps(data, sort_keys=True, separators=(',', ':'))
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def to_yaml(self) -> str:
        head = {'format': FORMAT, 'hash': self.hash}
        return yaml.safe_dump({**head, **self.data}, sort_keys=False)


def load(path=None, quick: bool = False, overrides: dict | None = None,
         protocol: str | None = None) -> ReplicateConfig:
    """Defaults, then ``protocol``'s preset, then the file at ``path``, then ``quick``'s
    overrides, then ``overrides``."""
    data = copy.deepcopy(DEFAULTS)
    given = read_yaml(path) if path is not None else {}
    protocol = protocol if protocol is not None else given.get('protocol')
    if protocol is not None:
        if not isinstance(protocol, str) or protocol not in PROTOCOLS:
            raise ValueError(f'protocol must be one of {sorted(PROTOCOLS)}, got {protocol!r}')
        data = merge(data, {**PROTOCOLS[protocol], 'protocol': protocol}, 'protocol')
    if path is not None:
        data = merge(data, {**given, **({'protocol': protocol} if protocol else {})},
                     str(path))
    if quick:
        data = merge(data, data['quick'], 'quick')
    if overrides:
        data = merge(data, overrides, 'command line')
    return build(data)


def read_yaml(path) -> dict:
    path = Path(path)
    with path.open() as f:
        try:
            loaded = yaml.safe_load(f)
        except yaml.YAMLError as exc:
            raise ValueError(f'{path} is not valid YAML: {" ".join(str(exc).split())}') from None
    loaded = loaded or {}
    if not isinstance(loaded, dict):
        raise ValueError(f'{path} must hold a mapping of settings, got {type(loaded).__name__}')
    loaded.pop('format', None)
    loaded.pop('hash', None)       # a results directory's config.yaml can be read back
    reality = loaded.get('reality')
    if isinstance(reality, dict) and isinstance(reality.get('effects'), str):
        reality['effects'] = str(path.parent / reality['effects'])   # beside the file
    if isinstance(loaded.get('diagnosed'), str):
        loaded['diagnosed'] = str(path.parent / loaded['diagnosed'])
    return loaded


def merge(base: dict, update: dict, source: str, where: str = '') -> dict:
    """``update`` laid over ``base``; nested mappings merge (an empty default is free-form)."""
    if not isinstance(update, dict):
        raise ValueError(f'{source}: {where or "settings"} must be a mapping, got {update!r}')
    out = dict(base)
    for key, value in update.items():
        name = f'{where}.{key}' if where else key
        if key not in base:
            raise ValueError(f'{source}: unknown setting {name!r}; known: {sorted(base)}')
        if isinstance(base[key], dict) and base[key]:
            out[key] = merge(base[key], value, source, name)
        else:
            out[key] = copy.deepcopy(value)
    return out


def build(data: dict) -> ReplicateConfig:
    """Check the plain settings and make the typed config; errors name the setting."""
    if data['protocol'] not in PROTOCOLS:
        raise ValueError(f"protocol must be one of {sorted(PROTOCOLS)}, "
                         f"got {data['protocol']!r}")
    seed = _integer(data, 'seed', 0)
    trials = _integer(data, 'trials', 2)
    test_episodes = _integer(data, 'test_episodes', 1)
    groups = data['dependence_groups']
    distribution = data['distribution']
    if not isinstance(data['levels'], list):
        raise ValueError(f'levels must be a list of noise levels, got {data["levels"]!r}')
    levels = tuple(_level(spec, groups, distribution, i) for i, spec in enumerate(data['levels']))
    if not levels:
        raise ValueError('levels: at least one noise level is needed')
    for what in ('label', 'figure'):
        names = [getattr(level, what) for level in levels]
        if len(set(names)) != len(names):
            raise ValueError(f'levels: each {what} must be unique, got {names}')
    backend = data['backend']
    for name, allowed in (('simulation', SIMULATION_BACKENDS), ('reality', REALITY_BACKENDS)):
        if backend[name] not in allowed:
            raise ValueError(f'backend.{name} must be one of {allowed}, got {backend[name]!r}')
    plain = {k: v for k, v in copy.deepcopy(data).items() if k != 'quick'}
    _integer(plain['reality'], 'robots', 1, 'reality.')
    _integer(plain['reality'], 'seed', 0, 'reality.')
    start = plain['reality']['start_bearing_deg']
    if start is not None and (isinstance(start, bool) or not isinstance(start, (int, float))
                              or not -180.0 <= start <= 180.0):
        raise ValueError(f'reality.start_bearing_deg must be null or degrees in [-180, 180], '
                         f'got {start!r}')
    plain['reality']['effects'] = effects_from(plain['reality']['effects']).to_dict()
    diagnosed = None
    if plain['diagnosed'] is not None:
        plain['diagnosed'] = fitted.parameters(plain['diagnosed'])
        sim = fitted.simulator(plain['diagnosed'])
        diagnosed = Condition('', fitted.NAME, sim.noise, tuple(sim.effects))
    phase2 = _typed(EAConfig, data, 'phase2')
    return ReplicateConfig(
        data=plain, seed=seed, trials=trials, test_episodes=test_episodes, levels=levels,
        phase1=_typed(EAConfig, data, 'phase1'), phase2=phase2,
        task=_typed(Task, data, 'task'), world=_typed(World, data, 'world'),
        reality=plain['reality'], backend=plain['backend'],
        ceiling=_ceiling(plain['ceiling'], phase2), diagnosed=diagnosed)


def _ceiling(spec: dict, phase2: EAConfig) -> EAConfig | None:
    """Phase 2 with the ceiling arm's budget, or None when the arm is off."""
    if not isinstance(spec['enabled'], bool):
        raise ValueError(f"ceiling.enabled must be true or false, got {spec['enabled']!r}")
    _integer(spec, 'population', 2, 'ceiling.')
    _integer(spec, 'generations', 1, 'ceiling.')
    budget = dataclasses.replace(phase2, population=spec['population'],
                                 generations=spec['generations'])
    return budget if spec['enabled'] else None


def _integer(data: dict, name: str, low: int, where: str = '') -> int:
    value = data[name]
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise ValueError(f'{where}{name} must be an integer >= {low}, got {value!r}')
    return value


def effects_from(spec) -> EffectsConfig:
    """The emulator's effects from a mapping or the path of a YAML file; written out in full,
    so the settings beside the results say what the emulated reality did."""
    if isinstance(spec, str):
        return EffectsConfig.load(spec)
    return EffectsConfig.from_dict(spec, 'reality.effects')


def _typed(cls, data: dict, name: str):
    try:
        return cls(**data[name])
    except (TypeError, ValueError) as exc:
        raise ValueError(f'{name}: {exc}') from None


def _level(spec, groups, distribution: str, index: int) -> Level:
    where = f'levels[{index}]'
    if not isinstance(spec, dict) or set(spec) != {'label', 'figure', *MODELS}:
        raise ValueError(f"{where} must have exactly the keys label, figure, combination "
                         f"({{dependent, independent}}) and independent (a level), got {spec!r}")
    combo = spec['combination']
    if not isinstance(combo, dict) or set(combo) != {'dependent', 'independent'}:
        raise ValueError(f'{where}.combination must be {{dependent: d, independent: i}}, '
                         f'got {combo!r}')
    label, figure = str(spec['label']), str(spec['figure'])
    try:
        noises = (NoiseModel('combination', combo['dependent'], combo['independent'],
                             groups, distribution),
                  NoiseModel('independent', 0.0, spec['independent'], groups, distribution))
    except ValueError as exc:
        raise ValueError(f'{where} ({label}): {exc}') from None
    return Level(label, figure, tuple(Condition(label, m, n) for m, n in zip(MODELS, noises)))
