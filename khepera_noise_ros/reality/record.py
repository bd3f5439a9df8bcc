"""Record a robot driven in this process, as ``khepera-noise record`` records one through
the hardware bridge: the same protocols, episodes and manifest, without ROS.

``robots`` is a body the bridge's backend drives (``reality.khepera_robot.Robots``: an
``InProcessRobots`` over the emulated world, or over any world with its methods); its
first robot is recorded, one episode after the other, so effects that carry over
(drift, a lag) carry over as on one real robot.  Stationary: one episode of ``samples``
readings per condition and heading, the robot held still (power 0), the lamp placed at
the heading.  Closed loop: ``episodes`` episodes of the task driven by a genome's
network; the lamp's bearing is not recorded unless ``headings`` (a tracked robot).
"""
from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np

from ..core import network
from ..core.khepera import World
from ..core.task import Task
from ..recording import FORMAT, Recording, concatenate
from .khepera_robot import KheperaRobots, Robots
from .world import CONDITIONS, SECTION2

HEADINGS = (-60.0, -20.0, 0.0, 30.0, 90.0)


def conditions(names: Sequence[str] = SECTION2) -> dict[str, dict]:
    """Lighting conditions by name, as the recorder declares them to the robot."""
    unknown = [n for n in names if n not in CONDITIONS]
    if unknown:
        raise ValueError(f'unknown condition(s) {unknown}; known: {sorted(CONDITIONS)}')
    return {n: {'lamp_distance_mm': float(CONDITIONS[n].lamp_distance_mm),
                'ambient': float(CONDITIONS[n].ambient)} for n in names}


def _manifest(protocol: str, declared: dict, source: str) -> dict:
    return {'format': FORMAT, 'source': source, 'sample_period_s': 1.0, 'protocol': protocol,
            'conditions': declared}


def stationary(robots: Robots, names: Sequence[str] = SECTION2,
               headings: Sequence[float] = HEADINGS, samples: int = 60, seed: int = 0,
               world: World = World(), source: str = 'hardware') -> Recording:
    """The section-2 protocol: ``samples`` readings per condition and heading."""
    declared = conditions(names)
    manifest = _manifest('stationary', declared, source)
    manifest.update(headings_deg=[float(h) for h in headings], samples_per_episode=samples)
    parts, episode = [], 0
    for label, values in declared.items():
        env = KheperaRobots(robots, dataclasses.replace(world, **values),
                            Task(steps=samples, perturbation_deg=0.0))
        for heading in headings:
            rows = [env.reset([seed + episode], robots=1, bearing_deg=float(heading))[0]]
            while (r := env.step(np.ones(1, int), np.zeros(1, int))) is not None:
                rows.append(r[0])
            parts.append(_rows(episode, label, np.array(rows, np.float64), float(heading)))
            episode += 1
    return concatenate(parts, manifest)


def closed_loop(robots: Robots, genome: np.ndarray, episodes: int = 40, condition: str = 'task',
                task: Task = Task(), seed: int = 0, world: World = World(),
                source: str = 'hardware', headings: bool = False) -> Recording:
    """``episodes`` episodes of the task, the robot driven by ``genome``'s network."""
    genome = network.check_genomes(genome)[0]
    declared = conditions((condition,))
    manifest = _manifest('closed_loop', declared, source)
    manifest.update(genome=genome.tolist(), task=dataclasses.asdict(task))
    weights = network.unpack(genome[None])
    env = KheperaRobots(robots, dataclasses.replace(world, **declared[condition]), task)
    parts = []
    for episode in range(episodes):
        readings = env.reset([seed + episode], robots=1)
        rows, turns, bearing = [], [], []
        while readings is not None:
            direction, power = network.act(weights, readings.astype(np.float32))
            rows.append(readings[0].copy())
            turns.append((direction[0], power[0]))
            bearing.append(float(env.bearing_deg[0]) if headings and env.bearing_deg
                           is not None else np.nan)
            readings = env.step(direction, power)
        part = _rows(episode, condition, np.array(rows, np.float64), np.array(bearing))
        part.direction, part.power = (np.array(t, np.float64) for t in zip(*turns))
        parts.append(part)
    return concatenate(parts, manifest)


def _rows(episode: int, label: str, readings: np.ndarray, heading: object) -> Recording:
    n = len(readings)
    empty = np.full(n, np.nan)
    return Recording(np.full(n, episode, np.int64), np.arange(n, dtype=np.int64),
                     np.broadcast_to(np.asarray(heading, np.float64), (n,)).copy(),
                     np.full(n, label), readings, empty, empty.copy(), {})
