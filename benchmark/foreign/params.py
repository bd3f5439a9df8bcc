"""A foreign robot's parameter file: what it holds, its limits, and reading and writing it.

One YAML file per robot (``robots/*.yaml``).  Every number is checked against the
limits below when the file is read; a bad file is one ``ValueError`` line naming the
file, the key, the value and what is allowed.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

FORMAT = 'khepera-foreign-robot/1'
SENSORS = 8
DYNAMICS = ('lag', 'delay', 'lag_delay')
STEPS = (1, 2, 3, 4)

# (section, key): (low, high, per_sensor).  Per-sensor values are lists of 8.
LIMITS = {
    ('light', 'lamp_power'): (0.1, 100.0, False),
    ('light', 'lamp_near_mm'): (1.0, 1000.0, False),
    ('light', 'room_flux'): (0.0, 20.0, False),
    ('light', 'axis_deg'): (-180.0, 180.0, True),
    ('light', 'width_ccw_deg'): (3.0, 120.0, True),
    ('light', 'width_cw_deg'): (3.0, 120.0, True),
    ('light', 'shape'): (0.5, 8.0, True),
    ('light', 'leak'): (0.0, 0.5, True),
    ('light', 'sensitivity'): (0.05, 20.0, True),
    ('light', 'dark'): (100.0, 525.0, True),
    ('light', 'floor'): (0.0, 300.0, True),
    ('light', 'hill'): (0.3, 5.0, True),
    ('actuator', 'gain'): (0.2, 3.0, False),
    ('actuator', 'asymmetry'): (-0.5, 0.5, False),
    ('actuator', 'exponent'): (0.4, 2.5, False),
    ('actuator', 'dead_band_deg'): (0.0, 20.0, False),
    ('actuator', 'backlash_deg'): (0.0, 10.0, False),
    ('actuator', 'scatter'): (0.0, 0.5, False),
    ('actuator', 'jitter_deg'): (0.0, 5.0, False),
    ('dynamics', 'brighten'): (0.05, 1.0, False),
    ('dynamics', 'darken'): (0.05, 1.0, False),
    ('dynamics', 'delay'): (0.0, 3.0, False),
    ('noise', 'flicker'): (0.0, 0.3, False),
    ('noise', 'flicker_samples'): (1.0, 10000.0, False),
    ('noise', 'shot'): (0.0, 3.0, False),
}
SECTIONS = {'light', 'actuator', 'dynamics', 'noise'}
CHOICES = {('dynamics', 'kind'): DYNAMICS, ('noise', 'step'): STEPS}
TOP = {'format', 'name', 'drawn', 'unit_seed', *SECTIONS}


def check(data, source: str = 'robot') -> dict:
    """``data`` as a robot's parameters (numbers as floats, per-sensor lists as arrays), or
    a one-line ValueError naming ``source``, the key, the value and what is allowed."""
    def fail(key, value, allowed):
        raise ValueError(f'{source}: {key} must be {allowed}, got {value!r}')

    if not isinstance(data, dict):
        fail('the file', type(data).__name__, 'a mapping of the sections ' + str(sorted(TOP)))
    if data.get('format') != FORMAT:
        fail('format', data.get('format'), repr(FORMAT))
    unknown = set(data) - TOP
    if unknown:
        fail('the top level', sorted(unknown)[0], f'one of {sorted(TOP)}')
    if not isinstance(data.get('unit_seed'), int) or isinstance(data.get('unit_seed'), bool) \
            or data['unit_seed'] < 0:
        fail('unit_seed', data.get('unit_seed'), 'an integer >= 0')
    if not isinstance(data.get('drawn', {}), dict):
        fail('drawn', data['drawn'], 'a mapping (generator, seed, index)')
    out = {'format': FORMAT, 'name': str(data.get('name', source)),
           'drawn': dict(data.get('drawn') or {}), 'unit_seed': int(data['unit_seed'])}
    for section in sorted(SECTIONS):
        given = data.get(section)
        if not isinstance(given, dict):
            fail(section, given, 'a mapping')
        wanted = {k for s, k in [*LIMITS, *CHOICES] if s == section}
        extra, missing = set(given) - wanted, wanted - set(given)
        if extra or missing:
            key = sorted(extra or missing)[0]
            fail(f'{section}.{key}', given.get(key, '(missing)'),
                 f'one of the keys {sorted(wanted)}' if extra else 'given')
        out[section] = {}
        for key, value in given.items():
            name = f'{section}.{key}'
            if (section, key) in CHOICES:
                if value not in CHOICES[section, key]:
                    fail(name, value, f'one of {CHOICES[section, key]}')
                out[section][key] = value
                continue
            low, high, per_sensor = LIMITS[section, key]
            shape = (SENSORS,) if per_sensor else ()
            allowed = (f'{SENSORS} numbers, each' if per_sensor else 'a number') + \
                f' in [{low}, {high}]'
            try:
                array = np.asarray(value, np.float64)
            except (TypeError, ValueError):
                fail(name, value, allowed)
            if array.shape != shape or isinstance(value, bool) or not np.isfinite(array).all() \
                    or (array < low).any() or (array > high).any():
                fail(name, value, allowed)
            out[section][key] = array if per_sensor else float(array)
    _check_together(out, fail)
    return out


def _check_together(p: dict, fail) -> None:
    """Values that are valid alone but not together."""
    light, dyn = p['light'], p['dynamics']
    low = np.flatnonzero(light['floor'] >= light['dark'] - 10.0)
    if low.size:
        fail(f'light.floor[{low[0]}]', float(light['floor'][low[0]]),
             f'at least 10 below light.dark[{low[0]}] = {light["dark"][low[0]]}')
    if dyn['kind'] == 'lag' and dyn['delay'] != 0.0:
        fail('dynamics.delay', dyn['delay'], '0 for kind lag')
    if dyn['kind'] == 'delay' and (dyn['brighten'], dyn['darken']) != (1.0, 1.0):
        fail('dynamics.brighten', dyn['brighten'], '1.0 (and darken 1.0) for kind delay')


def load(path) -> dict:
    """A robot's checked parameters from its YAML file."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise ValueError(f'{path}: cannot read the robot file ({exc.strerror})') from None
    except yaml.YAMLError as exc:
        first = str(exc).splitlines()[0] if str(exc) else 'bad YAML'
        raise ValueError(f'{path}: not YAML ({first})') from None
    return check(data, str(path))


def plain(p: dict) -> dict:
    """The parameters as YAML-ready builtins (rounded to 4 significant digits)."""
    def tidy(v):
        if isinstance(v, np.ndarray):
            return [tidy(x) for x in v.tolist()]
        if isinstance(v, float):
            return float(f'{v:.4g}')
        if isinstance(v, dict):
            return {k: tidy(x) for k, x in v.items()}
        return v
    return {k: tidy(v) for k, v in p.items()}


def save(p: dict, path) -> Path:
    """Write ``p`` (checked first) to ``path``; refuses to overwrite a drawn robot."""
    path = Path(path)
    if path.exists():
        raise ValueError(f'{path} exists: a drawn robot is written once and never redrawn')
    data = plain(p)
    check(data, str(path))
    path.write_text('# A foreign Khepera (benchmark/foreign, docs/foreign-robots.md); '
                    'drawn once, never edited.\n' + yaml.safe_dump(data, sort_keys=False))
    return path
