"""Emulate Khepera robots on pseudo-terminals: the stand-in for the physical robot.

Prints one device path per robot on standard output, then answers the
Khepera serial protocol on each until Ctrl-C.  Point the hardware bridge's
``ports`` parameter at the printed paths.  The emulated world carries effects
the simulator does not model (by default "the real robot", config/emulator.yaml);
``--config`` loads others, ``--write-config`` writes the settings in use.
``--measure`` instead reproduces the paper's section 2 measurement (two adjacent
sensors, a still robot, four lighting conditions) and prints it.
"""
from __future__ import annotations

import signal
import sys
import threading
from pathlib import Path

import numpy as np

from ..reality.effects import EffectsConfig
from ..reality.emulator import Emulator
from ..reality.world import CONDITIONS, SECTION2, EmulatedWorld, stationary
from ..synchrony import PAPER_CORRELATION

HELP = 'emulate Kheperas on pseudo-terminals (the stand-in for the real robot)'


def add_arguments(parser) -> None:
    parser.add_argument('--robots', type=int, default=1, help='robots, one device each')
    parser.add_argument('--config', type=Path, metavar='YAML',
                        help='effects file (default: the real robot, config/emulator.yaml)')
    parser.add_argument('--no-effects', action='store_true',
                        help='no effects, only each sensor\'s independent noise')
    parser.add_argument('--seed', type=int, default=0, help='seed of the world\'s randomness')
    parser.add_argument('--condition', choices=sorted(CONDITIONS), default='task',
                        help='lighting condition until a bridge declares one')
    parser.add_argument('--fault-rate', type=float, default=0.0, metavar='P',
                        help='fraction of replies lost, garbled or cut short at random')
    parser.add_argument('--link', metavar='PREFIX',
                        help='also make symlinks PREFIX0, PREFIX1, ... to the devices')
    parser.add_argument('--write-config', type=Path, metavar='YAML',
                        help='write the effects in use to this file and exit')
    parser.add_argument('--measure', action='store_true',
                        help='print the section 2 correlations of this world and exit')
    parser.add_argument('--samples', type=int, default=600,
                        help='samples per condition for --measure')


def effects_from_args(args) -> EffectsConfig:
    if args.no_effects and args.config:
        raise ValueError('give either --config or --no-effects, not both')
    if args.no_effects:
        return EffectsConfig.none()
    return EffectsConfig.load(args.config) if args.config else EffectsConfig.real_robot()


def run(args) -> int:
    if args.robots < 1:
        raise ValueError(f'--robots must be at least 1, got {args.robots}')
    config = effects_from_args(args)
    if args.write_config:
        print(f'wrote {config.save(args.write_config)}')
        return 0
    if args.measure:
        print(measure(config, args.seed, args.samples))
        return 0
    world = EmulatedWorld(config, seed=args.seed, robots=args.robots)
    world.set_condition(args.condition)
    return serve(Emulator(world, fault_rate=args.fault_rate, seed=args.seed), args.link)


def serve(emulator: Emulator, link: str | None) -> int:
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    links = [Path(f'{link}{i}') for i in range(len(emulator.ports))] if link else []
    with emulator:
        for path, port in zip(links, emulator.ports):
            path.unlink(missing_ok=True)
            path.symlink_to(port)
        for port in emulator.ports:
            print(port, flush=True)
        enabled = ', '.join(emulator.world.config.enabled) or 'none'
        print(f'khepera-noise emulate: {len(emulator.ports)} robot(s), effects: {enabled}; '
              f'Ctrl-C to stop', file=sys.stderr, flush=True)
        try:
            while not stop.wait(0.2):
                pass
        except KeyboardInterrupt:
            pass
        finally:
            for path in links:
                path.unlink(missing_ok=True)
    print('khepera-noise emulate: stopped', file=sys.stderr)
    return 0


def measure(config: EffectsConfig, seed: int, samples: int, pair=(2, 3)) -> str:
    """Section 2's table: levels, spread and correlation of two adjacent sensors."""
    if samples < 3:
        raise ValueError(f'--samples must be at least 3, got {samples}')
    a, b = pair
    rows = [f'{"condition":20s} {"mean s2":>8s} {"mean s3":>8s} {"sd s2":>6s} {"range s2":>9s} '
            f'{"r(s2,s3)":>9s} {"paper r":>8s}']
    for name in SECTION2:
        x = stationary(EmulatedWorld(config, seed=seed), name, samples)
        r = np.corrcoef(x[:, a], x[:, b])[0, 1]
        paper = PAPER_CORRELATION.get(name)
        rows.append(f'{name:20s} {x[:, a].mean():8.1f} {x[:, b].mean():8.1f} '
                    f'{x[:, a].std():6.2f} {np.ptp(x[:, a]):9.0f} {r:9.2f} '
                    + (f'{paper:8.2f}' if paper is not None else f'{"-":>8s}'))
    return '\n'.join(rows)
