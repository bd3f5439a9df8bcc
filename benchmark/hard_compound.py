"""Hard compound cases for ``blind_compound.py --hard``: a strong loop effect beside weaker
sensor effects of various shapes (benchmark code, not a test).

Each case has a sensor latency of 1-3 samples and/or a turn error (the loop effect,
whose closed-loop discrepancy dwarfs a sensor effect's) and 1-3 sensor effects drawn
near the edge of what the recordings can show, in shapes beyond the emulator's own
settings where it has none:

- ``spread_dark``: the emulator's flicker (one draw), exponent 0.5-3;
- ``spread_bright``: each sensor's own noise growing with *brightness*,
  sd = s x (525 - r) x ((525 - r) / 525) ** e (a process added here);
- ``lattice``: readings rounded to a step of 3-8;
- ``pairs``: noise shared in pairs or triples (the emulator's group noise);
- ``drift``: AR(1) wander of the gain, or steps of a gain shared by the sensors every
  150-400 samples (a process added here);
- ``limit``: a floor or ceiling touching few readings (the emulator's converter);
- ``gain_offset``: 1-3 sensors' calibration a little off;
- ``dropout``: isolated readings stuck at 0 or 525 on 1-3 sensors (added here).

Each shape has the vocabulary name a diagnosis should give it (``NAME``); shapes with
the same name are not drawn together.
"""
from __future__ import annotations

import numpy as np

import blind_gap
from khepera_noise_ros.core.khepera import DARK, SENSORS
from khepera_noise_ros.reality import effects as emu
from khepera_noise_ros.reality.effects.processes import Converter, Latency

NAME = {'spread_dark': 'intensity_dependent_noise', 'spread_bright': 'intensity_dependent_noise',
        'lattice': 'saturation_quantization', 'limit': 'saturation_quantization',
        'dropout': 'saturation_quantization', 'pairs': 'correlated_noise',
        'drift': 'temporal_drift', 'gain_offset': 'sensor_gain_offset'}
SHAPES = tuple(NAME)


class _OnSensors:
    """A process acting on ``sensors`` (a mask over the eight) with its own stream."""

    def __init__(self, sensors, seed: int):
        self.mask = np.isin(np.arange(SENSORS), sensors)
        self.rng = np.random.default_rng(seed)


class BrightSpread(_OnSensors):
    """Each sensor's own noise, sd growing with brightness (low readings)."""

    def __init__(self, sensors, strength: float, exponent: float, seed: int):
        super().__init__(sensors, seed)
        self.strength, self.exponent = strength, exponent

    def apply(self, level, z, rows):
        bright = np.clip(DARK - level, 0.0, DARK)
        sd = self.strength * bright * (bright / DARK) ** self.exponent
        noise = self.rng.standard_normal(level.shape) * sd
        return np.where(self.mask, level + noise, level)


class GainSteps(_OnSensors):
    """A gain shared by ``sensors`` that jumps to a new value every ``every`` samples."""

    def __init__(self, sensors, strength: float, every: int, seed: int):
        super().__init__(sensors, seed)
        self.strength, self.every = strength, every
        self.count, self.gain = 0, 0.0

    def apply(self, level, z, rows):
        if self.count % self.every == 0:
            self.gain = self.strength * self.rng.standard_normal()
        self.count += 1
        return np.where(self.mask, level * (1.0 + self.gain), level)


class Dropouts(_OnSensors):
    """With probability ``rate`` a reading of ``sensors`` is ``value``."""

    def __init__(self, sensors, rate: float, value: float, seed: int):
        super().__init__(sensors, seed)
        self.rate, self.value = rate, value

    def apply(self, level, z, rows):
        hit = (self.rng.random(level.shape) < self.rate) & self.mask
        return np.where(hit, self.value, level)


def _sensors(rng, low: int, high: int) -> list:
    return sorted(int(s) for s in rng.choice(SENSORS, size=int(rng.integers(low, high + 1)),
                                             replace=False))


def _shape(rng, shape: str, seed: int) -> tuple[dict, list, dict]:
    """(emulator settings by effect name, added processes with where they go, truth)."""
    if shape == 'spread_dark':
        s = {'strength': float(rng.uniform(0.008, 0.025)), 'exponent': float(rng.uniform(0.5, 3)),
             'location': tuple(blind_gap._arc(rng, 3, 8))}
        return {'intensity_dependent_noise': s}, [], s
    if shape == 'spread_bright':
        sensors = _sensors(rng, 3, 8)
        s = {'strength': float(rng.uniform(0.005, 0.02)), 'exponent': float(rng.uniform(0, 2)),
             'location': sensors}
        return {}, [('noise', BrightSpread(sensors, s['strength'], s['exponent'], seed))], s
    if shape == 'lattice':
        s = {'strength': float(rng.choice([2, 3, 4, 5])), 'location': tuple(range(SENSORS))}
        return {'saturation_quantization': s}, [], s
    if shape == 'limit':
        s = {'strength': 1.0, 'location': tuple(blind_gap._arc(rng, 2, 8))}
        if rng.random() < 0.5:
            s['high'] = float(rng.uniform(503, 508))
        else:
            s['low'] = float(rng.uniform(52, 75))
        return {'saturation_quantization': s}, [], s
    if shape == 'dropout':
        sensors = _sensors(rng, 1, 3)
        s = {'rate': float(rng.uniform(0.001, 0.005)), 'value': float(rng.choice([0, DARK])),
             'location': sensors}
        return {}, [('end', Dropouts(sensors, s['rate'], s['value'], seed))], s
    if shape == 'pairs':
        rest = list(rng.permutation(SENSORS))
        groups = []
        for _ in range(int(rng.integers(1, 3))):
            size = int(rng.integers(2, 4))
            groups.append(tuple(sorted(int(x) for x in rest[:size])))
            rest = rest[size:]
        s = {'strength': float(rng.uniform(0.006, 0.018)), 'location': tuple(groups)}
        return {'correlated_noise': s}, [], s
    if shape == 'drift':
        sensors = list(range(SENSORS)) if rng.random() < 0.5 else _sensors(rng, 2, 6)
        if rng.random() < 0.5:
            s = {'strength': float(rng.uniform(0.003, 0.01)),
                 'time_constant': float(rng.uniform(10, 80)), 'shared': bool(rng.random() < 0.5),
                 'location': tuple(sensors)}
            return {'temporal_drift': s}, [], s
        s = {'steps': float(rng.uniform(0.003, 0.01)), 'every': int(rng.integers(150, 401)),
             'location': sensors}
        return {}, [('noise', GainSteps(sensors, s['steps'], s['every'], seed))], s
    if shape == 'gain_offset':
        sensors = _sensors(rng, 1, 3)
        gains, offsets = [1.0] * SENSORS, [0.0] * SENSORS
        for x in sensors:
            gains[x] = 1.0 + float(rng.choice([-1, 1]) * rng.uniform(0.02, 0.06))
            offsets[x] = float(rng.uniform(-4, 4))
        s = {'gains': tuple(gains), 'offsets': tuple(offsets), 'location': tuple(sensors)}
        return {'sensor_gain_offset': s}, [], s
    raise ValueError(f'unknown shape {shape!r}; allowed: {", ".join(SHAPES)}')


def draw(rng, seed: int, shape: str | None = None) -> tuple:
    """(effect names, emulator configuration, added processes, truth per shape);
    ``shape``: one sensor shape always drawn among them (the others as before)."""
    settings, added, truth = {}, [], {}
    loop = rng.choice(['latency', 'turn', 'both'], p=[0.45, 0.3, 0.25])
    if loop in ('latency', 'both'):
        location = blind_gap.RING if rng.random() < 0.5 else blind_gap._arc(rng, 2, 6)
        settings['sensor_latency'] = {'strength': int(rng.integers(1, 4)),
                                      'location': tuple(location)}
        truth['latency'] = settings['sensor_latency']
    if loop in ('turn', 'both'):
        scale = rng.uniform(0.6, 0.85) if rng.random() < 0.5 else rng.uniform(1.15, 1.4)
        settings['actuator_turn_error'] = {'scale': float(scale),
                                           'strength': float(rng.uniform(0.0, 0.3))}
        truth['turn'] = settings['actuator_turn_error']
    names = set(settings)
    want, drawn = int(rng.integers(1, 4)), 0
    order = list(rng.permutation(SHAPES))
    if shape is not None:
        if shape not in SHAPES:
            raise ValueError(f'unknown shape {shape!r}; allowed: {", ".join(SHAPES)}')
        order = [shape] + [x for x in order if x != shape]
    for name in order:
        if drawn == want:
            break
        if NAME[name] in names:
            continue
        drawn += 1
        emulated, processes, s = _shape(rng, str(name), seed + len(truth))
        settings.update(emulated)
        added += processes
        names.add(NAME[name])
        truth[str(name)] = {k: list(v) if isinstance(v, tuple) else v for k, v in s.items()}
    base = emu.EffectsConfig.none(blind_gap.SENSOR_NOISE)
    config = base.only(*[n for n in settings], **settings)
    return sorted(names), config, added, truth


def robot(config: emu.EffectsConfig, added: list, seed: int):
    """The emulated robot with the added processes in its sensor chain: noise and gain
    processes before the latency (what the sensor measures is delayed) and before the
    converter, dropouts last."""
    world = blind_gap.robot(config, seed)
    chain = world._chain.chain          # the emulator has no setting for these shapes
    for where, process in added:
        if where == 'end':
            chain.append(process)
            continue
        at = next((i for i, p in enumerate(chain) if isinstance(p, (Latency, Converter))),
                  len(chain))
        chain.insert(at, process)
    return world


def plan(rng) -> dict:
    """How a case is recorded: closed-loop headings kept (a tracked robot) in half the
    cases, and in a quarter no stationary recording at all."""
    return {'headings': bool(rng.random() < 0.5), 'stationary': bool(rng.random() < 0.75)}


def loop_only(k: int, seed: int, tracked: bool = False) -> dict:
    """How case ``k`` is recorded in ``--loop-only``: a robot that logs only while it runs
    its task (20-30 episodes, no stationary part), headings kept in one case of four.
    ``tracked``: every case a tracked robot (headings kept), 20 episodes."""
    if tracked:
        return {'headings': True, 'stationary': False, 'episodes': 20}
    return {'headings': k % 4 == 3, 'stationary': False, 'episodes': 20 + seed % 11}
