"""The outside robot: the project's core simulator as the clean base, hidden effects on top.

The base is the simulator at its defaults (the paper's combination noise,
3 % dependent and 2 % independent), so without effects there is no gap.  A
stationary recording is taken as in the paper's section 2: one episode per
condition and heading, power 0, no knocks.  A closed-loop recording runs an
evolved controller on the task; the controller sees the readings after the
effects (and late, with latency), and the robot turns as the turn error says.
Recordings are written with the project's public writer and say only what an
experimenter would know (no noise model, source ``hardware``).
"""
from __future__ import annotations

from collections import deque

import numpy as np

from khepera_noise_ros.core import network
from khepera_noise_ros.core.khepera import World
from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.core.task import Episodes, Task
from khepera_noise_ros.recording import Recording

from .shapes import DARK

# the four lighting conditions of the paper's section 2, as the recorder names them
CONDITIONS = {'bulb_1ft': {'lamp_distance_mm': 14.0, 'ambient': 500.0},
              'bulb_2ft': {'lamp_distance_mm': 130.0, 'ambient': 500.0},
              'room_fluorescent': {'lamp_distance_mm': 10000.0, 'ambient': 250.0},
              'room_dark': {'lamp_distance_mm': 10000.0, 'ambient': 500.0}}
TASK_CONDITION = {'task': {'lamp_distance_mm': 5.0, 'ambient': 500.0}}
# best of `khepera-noise evolve --population 30 --generations 30 --seed 1` (fitness 0.77)
GENOME = [0.4393466144187148, 0.19806711480313477, -0.4258929735282351, 1.3318039005697795,
          -2.2586889913797337, -1.592312911082639, -2.025234125061308, -1.4740389918917831,
          -0.10475696800474377, -3.3770457764219843, 1.5566692203118848, 2.319841735238663,
          2.9215390550057774, 3.214507792583482, -0.37966881880291137, -3.500000701892673,
          1.8042151825019266, 3.0865171862181224, -0.18021605170281174, 0.5527934165607598]


def _finish(row: np.ndarray) -> np.ndarray:
    """What a Khepera reports: integers within 0..525."""
    return np.clip(np.rint(row), 0.0, DARK)


def stationary_clean(seed: int, headings, samples: int) -> Recording:
    """The clean stationary base, episodes in the order they were taken."""
    rows, meta = [], []
    task = Task(steps=samples, perturbation_deg=0.0)
    episode = 0
    for label, world in CONDITIONS.items():
        for heading in headings:
            env = Episodes(World(**world), NoiseModel(), task)
            readings = env.reset(seed + episode, robots=1, bearing_deg=heading)
            step = 0
            while readings is not None:
                rows.append(readings[0].astype(float))
                meta.append((episode, step, heading, label))
                readings = env.step(np.array([1]), np.array([0]))
                step += 1
            episode += 1
    n = len(rows)
    manifest = {'format': 'khepera-noise-recording/1', 'source': 'hardware',
                'sample_period_s': 1.0, 'protocol': 'stationary', 'conditions': CONDITIONS,
                'headings_deg': [float(h) for h in headings], 'samples_per_episode': samples}
    return Recording(
        episode=np.array([m[0] for m in meta]), step=np.array([m[1] for m in meta]),
        heading_deg=np.array([m[2] for m in meta], float),
        condition=np.array([m[3] for m in meta]), readings=np.array(rows),
        direction=np.full(n, np.nan), power=np.full(n, np.nan), manifest=manifest)


def stationary(seed: int, effects, headings, samples: int, rng) -> tuple[Recording, Recording]:
    """(clean, real): the base and the same samples through the effects, in time order."""
    clean = stationary_clean(seed, headings, samples)
    for e in effects:
        e.prepare(len(clean), clean.readings, rng)
    real = clean.readings.copy()
    for t in range(len(clean)):
        row = real[t]
        for e in effects:
            row = e.sense(t, row, rng)
        real[t] = _finish(row)
    return clean, Recording(clean.episode, clean.step, clean.heading_deg, clean.condition,
                            real, clean.direction, clean.power, dict(clean.manifest))


def closed_loop(seed: int, effects, episodes: int, rng, steps: int = 60) -> Recording:
    """Episodes of the task with the effects in the loop."""
    world = World(**TASK_CONDITION['task'])
    task = Task(steps=steps)
    weights = network.unpack(np.asarray(GENOME)[None, :])
    for e in effects:
        e.prepare(episodes * steps, None, rng)
    delay = max([e.delay for e in effects] + [0])
    cols = {k: [] for k in ('episode', 'step', 'heading', 'readings', 'direction', 'power')}
    t = 0
    for ep in range(episodes):
        env = Episodes(world, NoiseModel(), task)
        readings = env.reset(seed + ep, robots=1)
        late: deque = deque(maxlen=delay + 1)
        step = 0
        while readings is not None:
            row = readings[0].astype(float)
            for e in effects:
                row = e.sense(t, row, rng)
            late.append(_finish(row))
            seen = late[0]                       # delay samples ago (the first, at the start)
            direction, power = network.act(weights, seen[None, :].astype(np.float32))
            d, p = int(direction[0]), int(power[0])
            cols['episode'].append(ep)
            cols['step'].append(step)
            cols['heading'].append(float(env.bearing_deg[0]))
            cols['readings'].append(seen)
            cols['direction'].append(d)
            cols['power'].append(p)
            executed = p
            for e in effects:
                executed = e.actuate(executed, rng)
            readings = env.step(np.array([d]), np.array([executed]))
            step += 1
            t += 1
    manifest = {'format': 'khepera-noise-recording/1', 'source': 'hardware',
                'sample_period_s': 1.0, 'protocol': 'closed_loop',
                'conditions': TASK_CONDITION, 'genome': list(GENOME),
                'task': {'steps': steps, 'perturb_every': task.perturb_every,
                         'perturbation_deg': task.perturbation_deg}}
    return Recording(
        episode=np.array(cols['episode']), step=np.array(cols['step']),
        heading_deg=np.array(cols['heading']), condition=np.full(t, 'task'),
        readings=np.array(cols['readings']), direction=np.array(cols['direction'], float),
        power=np.array(cols['power'], float), manifest=manifest)
