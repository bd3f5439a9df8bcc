"""The emulated robot recorded as the blind benchmark records it, for the diagnosis's tests.

The same robot, protocols and controller as ``benchmark/blind_gap.py`` (which keeps its
own copy: a benchmark's figures must not move when a test helper does): a stationary
recording at fixed headings in five conditions, a closed-loop one of the task, and the
robot's effects with their true parameters in the diagnosis's vocabulary (an oracle
the diagnosis never sees).
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Sequence

import numpy as np
from scipy.special import ndtr

from ..core import evolution, network
from ..core.evaluation import CoreEvaluator
from ..core.noise import NoiseModel
from ..core.task import Task
from ..effects import (ActuatorTurnError, CorrelatedNoise, Effect, IntensityDependentNoise,
                       SensorGainOffset, SensorLatency, TemporalDrift)
from ..gap import split
from ..gap.compare import Comparison
from ..simconfig import SimConfig
from ..gap.target import Target
from ..reality import effects as emu
from ..reality.effects.config import SENSOR_DRAWS
from ..reality.effects.processes import SensorNoise
from ..reality.khepera_robot import InProcessRobots, KheperaRobots
from ..reality.world import CONDITIONS, EmulatedWorld
from ..recording import FORMAT, Recording

SENSOR_NOISE = 0.02
# the lamp on each sensor's axis in turn, in an order that lights and darkens every
# sensor several times
SWEEP = (10, -90, 45, -170, -10, 90, -45, 170)
STATIONARY = {'task': SWEEP, 'bulb_1ft': SWEEP, 'bulb_2ft': SWEEP, 'room_dark': (0,),
              'room_fluorescent': (0,)}
SAMPLES, REPEATS, SETTLE = 60, 2, 5
CLOSED_LOOP_EPISODES = 30
EIGHT = tuple(range(8))


class PaperSensorNoise(SensorNoise):
    """Sensor noise with getnoise's truncation toward zero, as the paper's C code does."""

    def apply(self, level: Any, z: Any, rows: Any) -> Any:
        u = ndtr(z[:, SENSOR_DRAWS])
        return level + np.trunc((2.0 * u - 1.0) * self.level * level)


def _truncates() -> bool:
    probe = SensorNoise(0.02).apply(np.full((1, 8), 50.3), np.full((1, emu.DRAWS), 0.8),
                                    np.array([0]))
    return bool(np.allclose(probe - 50.3, np.round(probe - 50.3)))


def robot(config: emu.EffectsConfig, seed: int, robots: int = 1) -> EmulatedWorld:
    """The emulated robot(s), their own noise made the paper's getnoise (truncated), so that
    a robot with no effects has no gap to the paper's simulator."""
    world = EmulatedWorld(config, seed=seed, robots=robots)
    if not _truncates():
        chain = world._chain.chain          # the emulator has no setting for this
        for i, process in enumerate(chain):
            if type(process) is SensorNoise:
                chain[i] = PaperSensorNoise(process.level)
    return world


def _manifest(protocol: str, conditions: Sequence[str],
              genome: Any = None) -> dict[str, Any]:
    m: dict[str, Any] = {'format': FORMAT, 'source': 'emulator', 'sample_period_s': 1.0,
                         'protocol': protocol,
                         'conditions': {c: dataclasses.asdict(CONDITIONS[c]) for c in conditions}}
    if genome is not None:
        m['genome'] = [float(g) for g in genome]
    return m


def record_stationary(world: EmulatedWorld, plan: dict[str, tuple[int, ...]] = STATIONARY,
                      samples: int = SAMPLES, repeats: int = REPEATS,
                      settle: int = SETTLE) -> Recording:
    """Readings at fixed headings: an episode is one condition; the sensors settle, then
    the robot is turned from heading to heading and read ``samples`` times at each."""
    rows, episode = [], 0
    for _ in range(repeats):
        for condition, headings in plan.items():
            world.set_condition(condition)
            world.set_bearing(headings[0])
            for _ in range(settle):
                world.read(0)
            t = 0
            for heading in headings:
                world.set_bearing(heading)
                for _ in range(samples):
                    rows.append((episode, t, heading, condition, world.read(0)))
                    t += 1
            episode += 1
    return _recording(rows, _manifest('stationary', list(plan)))


def record_closed_loop(world: EmulatedWorld, genome: Any, condition: str = 'task',
                       episodes: int = CLOSED_LOOP_EPISODES, task: Task = Task(), seed: int = 0,
                       headings: bool = False) -> Recording:
    """The task on the robot as the hardware bridge runs it; headings not recorded (as on
    a real robot) unless ``headings`` (a tracked robot)."""
    weights = network.unpack(np.asarray(genome)[None])
    robots = KheperaRobots(InProcessRobots(world), CONDITIONS[condition].world(), task)
    seeds = np.random.SeedSequence(seed).generate_state(episodes, np.uint32)
    rows = []
    for e, episode_seed in enumerate(seeds):
        readings = robots.reset([int(episode_seed)], bearing_deg=0.0)
        t = 0
        while readings is not None:
            direction, power = network.act(weights, readings.astype(np.float32))
            heading = float(robots.bearing_deg[0]) if headings else math.nan
            rows.append((e, t, heading, condition, readings[0].copy(), int(direction[0]),
                         int(power[0])))
            readings = robots.step(direction, power)
            t += 1
    return _recording(rows, _manifest('closed_loop', [condition], genome))


def _recording(rows: list[tuple[Any, ...]], manifest: dict[str, Any]) -> Recording:
    n = len(rows)
    turns = [r[5:] if len(r) > 5 else (math.nan, math.nan) for r in rows]
    return Recording(np.array([r[0] for r in rows]), np.array([r[1] for r in rows]),
                     np.array([r[2] for r in rows], float), np.array([r[3] for r in rows]),
                     np.array([r[4] for r in rows], float).reshape(n, 8),
                     np.array([t[0] for t in turns], float),
                     np.array([t[1] for t in turns], float), manifest)


def recordings(config: emu.EffectsConfig, seed: int, samples: int, episodes: int,
               genome: Sequence[float]) -> list[Recording]:
    """[stationary, closed loop] of one robot, the closed loop run by ``genome``."""
    world = robot(config, seed)
    return [record_stationary(world, STATIONARY, samples=samples),
            record_closed_loop(world, np.array(genome), episodes=episodes, seed=seed)]


def evolved_genome(seed: int) -> np.ndarray:
    """The controller the benchmark's closed-loop recordings run: evolved in the simulator."""
    evaluate = CoreEvaluator(noise=NoiseModel.independent_only(SENSOR_NOISE))
    eas = [evolution.SteadyStateEA(evolution.EAConfig(population=25, generations=30), s)
           for s in np.random.SeedSequence(seed).generate_state(4)]
    evolution.evolve(eas, evaluate)
    best: np.ndarray = max(eas, key=lambda e: e.best_fitness).best_genome
    return best


def simulator(config: emu.EffectsConfig, rounding: str = 'level') -> SimConfig:
    """The paper's independent model at the robot's own sensor noise."""
    return SimConfig(noise=NoiseModel.independent_only(config.sensor_noise, rounding=rounding))


def true_effects(config: emu.EffectsConfig) -> dict[str, Effect]:
    """The robot's enabled effects in the diagnosis's vocabulary, true parameters, in the
    order the robot applies them (the flicker's size depends on the calibrated level)."""
    out: dict[str, Effect] = {}
    g = config.sensor_gain_offset
    if g.enabled:
        draws = np.random.default_rng([g.unit_seed]).standard_normal((2, 8))
        out['sensor_gain_offset'] = SensorGainOffset(
            EIGHT, tuple(float(v) for v in np.round(1 + g.strength * draws[0], 5)),
            tuple(float(v) for v in np.round(g.offset_sd * draws[1], 4)))
    d = config.temporal_drift
    if d.enabled:
        out['temporal_drift'] = TemporalDrift(tuple(d.location), d.strength, d.time_constant,
                                              d.shared)
    f = config.intensity_dependent_noise
    if f.enabled:
        out['intensity_dependent_noise'] = IntensityDependentNoise(
            tuple(f.location), f.strength, f.exponent, 525.0, 0.0, 'dark', True)
    c = config.correlated_noise
    if c.enabled:
        out['correlated_noise'] = CorrelatedNoise(tuple(map(tuple, c.location)), c.strength)
    t = config.actuator_turn_error
    if t.enabled:
        out['actuator_turn_error'] = ActuatorTurnError(t.scale, t.strength)
    s = config.sensor_latency
    if s.enabled:
        out['sensor_latency'] = SensorLatency(tuple(s.location), s.strength)
    return out


def parts(recs: list[Recording], config: emu.EffectsConfig, seed: int = 0,
          replicates: int = 100) -> list[Target]:
    """The fitting and held-out targets, made as ``diagnose`` makes them."""
    full = Target(recs, simulator(config), seed, 'auto', replicates=replicates)
    fit_part, test_part = split.split(recs, ())
    return [Target([r for _, r in part], simulator(config), seed + k, 'auto',
                   replicates=replicates,
                   block_lengths=[full.block_lengths[i] for i, _ in part])
            for k, part in ((1, fit_part), (2, test_part))]


def by_family(c: Comparison) -> list[tuple[str, float]]:
    """[(statistic family, its part of the discrepancy)], largest first."""
    out: dict[str, float] = {}
    for k, z in zip(c.keys, c.z):
        out[k.family] = out.get(k.family, 0.0) + max(abs(float(z)) - 2.0, 0.0) ** 2
    return sorted(out.items(), key=lambda t: -t[1])
