"""The record protocols that identify the simulator's world (docs/identification.md):
a heading sweep (stationary placements round the circle) and a turn calibration
(turns of every power both ways between rests, from known placements)."""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from ..core.khepera import World

LAMP_OFF_MM = 1e4          # a condition with its lamp this far has no bearing to sweep
TURNS = 4                  # turns per placement, right and left in turn
POWERS = range(1, 10)


def sweep_headings(step: float, world: dict[str, Any], passes: int = 2) -> list[float]:
    """The sweep's headings in a condition: every ``step`` degrees round the circle with
    the lamp on, straight ahead alone with it off; each pass the other way round (so that
    alternate placements, the diagnosis's split, give each part every heading)."""
    if float(world.get('lamp_distance_mm', 0.0)) >= LAMP_OFF_MM:
        return [0.0] * passes
    once = [float(h) for h in np.arange(-180.0, 180.0, step)]
    return [h for k in range(passes) for h in (once if k % 2 == 0 else once[::-1])]


def turn_policy(power: int, rest: int) -> Callable[[np.ndarray], tuple[int, int]]:
    """Answers of one placement: power 0, and every ``rest`` readings a turn of ``power``,
    right then left in turn, ``TURNS`` times (called once per step, in order)."""
    count = [0]

    def policy(readings: np.ndarray) -> tuple[int, int]:
        count[0] += 1
        k = count[0] // rest - 1
        if count[0] % rest == 0 and 0 <= k < TURNS:
            return (1 if k % 2 == 0 else -1), power
        return 1, 0
    return policy


def turn_steps(rest: int) -> int:
    return rest * (TURNS + 1)


def placement(power: int) -> float:
    """Where the lamp is put before turns of ``power``: half a turn to the left of ahead, so
    the turns swing the front sensors through the lamp's light."""
    return -power * World().deg_per_power / 2.0


def ask(what: str) -> None:
    input(f'{what} and press Enter: ')


def stationary(args: Any, recorder: Any, executor: Any, params: Any, manifest: dict[str, Any],
               conditions: dict[str, dict[str, Any]], headings: Callable[[dict[str, Any]],
                                                                         list[float]],
               hold: Any, done: Any) -> None:
    """Placements at fixed headings in each condition, one episode each, answered with
    power 0; with ``--ask`` the experimenter is asked to place the robot each time."""
    params.set({'perturbation_deg': 0.0, 'steps': args.samples})
    done.manifest, episode = manifest, 0
    for label, world in conditions.items():
        params.set(world)
        if args.ask:
            ask(f'Set up condition {label} ({world})')
        for heading in headings(world):
            if args.ask and args.protocol == 'sweep':
                ask(f'Place the robot with the lamp at {heading:g} deg (CCW)')
            log = recorder.record_episode(executor, episode, args.seed + episode, args.samples,
                                          hold, heading)
            done.lost += [[episode, s] for s in log.lost]
            done.parts.append(log.recording(label, manifest, heading, acted=False))
            episode += 1


def turns(args: Any, recorder: Any, executor: Any, params: Any, manifest: dict[str, Any],
          world: dict[str, Any], done: Any) -> None:
    """The turn calibration: per repeat and power one placement, then ``TURNS`` turns
    between rests of ``--turn-rest`` readings.  Headings the robot does not report are
    left empty after the placement (the diagnosis infers them through a sweep)."""
    label = f'turns_{args.condition}'
    steps = turn_steps(args.turn_rest)
    task = params.get(['perturb_every'])
    manifest.update(conditions={label: world}, calibration='turns', turn_rest=args.turn_rest,
                    task={'steps': steps, **task, 'perturbation_deg': 0.0})
    params.set({'steps': steps, 'perturbation_deg': 0.0, **world})
    done.manifest, episode = manifest, 0
    for _ in range(args.turn_repeats):
        for power in POWERS:
            start = placement(power)
            if args.ask:
                ask(f'Place the robot with the lamp at {start:g} deg (CCW)')
            log = recorder.record_episode(executor, episode, args.seed + episode, steps,
                                          turn_policy(power, args.turn_rest), start)
            done.lost += [[episode, s] for s in log.lost]
            rec = log.recording(label, manifest, None, acted=True)
            rec.heading_deg[(rec.step == 0) & np.isnan(rec.heading_deg)] = start
            done.parts.append(rec)
            episode += 1
