"""A fitted simulator's parameters (a fitted_params.yaml) for the diagnosed condition of
``replicate`` and ``sweep``: read, checked, and kept as the noise and effects it holds."""
from __future__ import annotations

import json
from pathlib import Path

import yaml

from .. import simconfig
from ..effects import DEFAULT, REGISTRY

NAME = 'diagnosed'
KEYS = simconfig.NOISE_KEYS + ('effects',)


def parameters(spec, source: str = 'diagnosed') -> dict:
    """The condition's simulator parameters (noise and effects) from a params file's path
    or a mapping of them; a bad file or an unknown effect is one line naming it."""
    if isinstance(spec, (str, Path)):
        path = Path(spec)
        if not path.is_file():
            raise ValueError(f'--params {path}: no such params file (a fitted_params.yaml '
                             f'from khepera-noise diagnose)')
        try:
            data = yaml.safe_load(path.read_text())
        except yaml.YAMLError as exc:
            raise ValueError(f'{path}: not valid YAML: {" ".join(str(exc).split())}') from None
        _check_names(_effects_text(data), str(path))
        config = simconfig.load(path)
    elif isinstance(spec, dict):
        _check_names(spec.get('effects', ''), source)
        config = simconfig.from_parameters(spec, source)
    else:
        raise ValueError(f'{source} must be the path of a params file or a mapping of its '
                         f'parameters, got {spec!r}')
    values = config.parameters()
    return {k: values[k] for k in KEYS}


def _effects_text(data) -> object:
    """The ``effects`` parameter of a params file's node sections (or a flat mapping)."""
    if not isinstance(data, dict):
        return ''
    for section in data.values():
        params = section.get('ros__parameters') if isinstance(section, dict) else None
        if isinstance(params, dict) and 'effects' in params:
            return params['effects']
    return data.get('effects', '')


def _check_names(text, source: str) -> None:
    if not isinstance(text, str) or not text.strip():
        return
    try:
        entries = json.loads(text)
    except json.JSONDecodeError:
        return                              # simconfig says what is wrong with the JSON
    for entry in entries if isinstance(entries, list) else []:
        name = entry.get('name') if isinstance(entry, dict) else entry
        if name not in REGISTRY:
            raise ValueError(f"{source}: unknown effect {name!r}; known effects: "
                             f"{', '.join(DEFAULT)} (and empirical_noise, the remainder model)")


def simulator(params: dict) -> simconfig.SimConfig:
    """The simulator of checked ``parameters`` (the replication's world and task aside)."""
    return simconfig.from_parameters(params, NAME)
