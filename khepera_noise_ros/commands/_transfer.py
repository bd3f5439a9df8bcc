"""The diagnose command's transfer experiment: the robot it tests on, its progress on
stderr, and do no harm: a fitted simulator whose controllers do worse on the robot is not
written as the recommended fitted_params.yaml."""
from __future__ import annotations

import argparse
import json
import sys
from contextlib import contextmanager
from pathlib import Path

from .. import simconfig
from ..core import evolution
from ..core.evaluation import episode_fitness
from ..experiment import transfer, transfer_report, transfer_stats
from ..files import atomic_write_text, write_json

REJECTED = {'params': 'fitted_params.rejected.yaml',
            'params_with_remainder': 'fitted_params_with_remainder.rejected.yaml'}
CAPACITY = 256          # emulated robots driven at once


def add_arguments(parser) -> None:
    t = parser.add_argument_group(
        'transfer experiment (with a closed-loop recording): evolve in the stock, the '
        "paper's two noise models' and the diagnosed simulator, and test on the robot")
    t.add_argument('--transfer-emulator', metavar='EFFECTS_YAML',
                   help="the robot is the emulated robot of this effects file ('real_robot' "
                        "for the emulator's default, config/emulator.yaml)")
    t.add_argument('--transfer-port', nargs='+', metavar='PORT',
                   help='the robot is the Khepera(s) on these serial ports')
    t.add_argument('--transfer-trials', type=int, default=transfer.TRIALS,
                   help='EA runs per arm')
    t.add_argument('--transfer-test-episodes', type=int, default=transfer.TEST_EPISODES,
                   help="episodes of each best's test on the robot")
    t.add_argument('--transfer-population', type=int, default=transfer.EA.population)
    t.add_argument('--transfer-generations', type=int, default=transfer.EA.generations)
    t.add_argument('--transfer-ceiling', action=argparse.BooleanOptionalAction, default=None,
                   help='also evolve on the robot with the same budget (the robot-trained '
                        'arm); default: on for the emulator, off for ports')
    t.add_argument('--no-progress', action='store_true', help='no progress bar')


def wanted(args) -> bool:
    """Whether a transfer experiment is asked for; its settings checked before anything runs."""
    if args.transfer_emulator and args.transfer_port:
        raise ValueError('choose one of --transfer-emulator and --transfer-port')
    for name, value, low in (('--transfer-trials', args.transfer_trials, 2),
                             ('--transfer-test-episodes', args.transfer_test_episodes, 1)):
        if value < low:
            raise ValueError(f'{name} must be at least {low}, got {value}')
    ea_of(args)
    return bool(args.transfer_emulator or args.transfer_port)


def ceiling(args) -> bool:
    """The robot-trained arm: asked for, else on for the emulator and off for ports."""
    return args.transfer_ceiling if args.transfer_ceiling is not None \
        else bool(args.transfer_emulator)


def closed_loop(recordings):
    """The closed-loop recording whose condition the robot is tested in."""
    from ..gap.protocol import kind
    loops = [r for r in recordings if kind(r) == 'closed_loop']
    if not loops:
        raise ValueError('the transfer experiment needs a closed-loop recording')
    return loops[0]


def ea_of(args) -> evolution.EAConfig:
    return evolution.EAConfig(population=args.transfer_population,
                              generations=args.transfer_generations, best='retest',
                              retest_episodes=transfer.EA.retest_episodes)


@contextmanager
def robot(args, world, config: simconfig.SimConfig):
    """(evaluate, where): the robot the arms are tested on; ports closed on exit."""
    if args.transfer_port:
        from ..reality.khepera_robot import KheperaRobots
        ports = list(args.transfer_port)
        env = KheperaRobots.on_ports(ports, world, config.task)
        try:
            yield _chunked(env, len(ports)), f"the Khepera(s) on {', '.join(ports)}"
        finally:
            env.close()
        return
    from ..reality.effects import EffectsConfig
    from ..reality.khepera_robot import InProcessRobots, KheperaRobots
    from ..reality.world import EmulatedWorld
    name = args.transfer_emulator
    physics = EffectsConfig.real_robot() if name == 'real_robot' else EffectsConfig.load(name)
    env = KheperaRobots(InProcessRobots(EmulatedWorld(physics, args.seed, CAPACITY, world,
                                                      start_bearing_deg=0.0)),
                        world, config.task)
    yield _chunked(env, CAPACITY), f'the emulated robot ({name})'


def _chunked(env, capacity: int):
    return lambda genomes, seeds: episode_fitness(env, genomes, seeds, capacity)


class Bar:
    """A tqdm bar on stderr: the stage and the episodes played (simulated and real)."""

    def __init__(self, enabled: bool):
        self.enabled, self.bar = enabled, None

    def start(self, total: int) -> None:
        from tqdm import tqdm
        self.bar = tqdm(total=total, unit='ep', file=sys.stderr, disable=not self.enabled,
                        dynamic_ncols=True, mininterval=0.5)

    def stage(self, text: str) -> None:
        if self.bar is not None:
            self.bar.set_description_str(f'transfer: {text}', refresh=False)

    def advance(self, episodes: int) -> None:
        if self.bar is not None:
            self.bar.update(episodes)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def run(args, simulators: dict, reality) -> dict:
    """The measured protocol; its ``transfer`` block (``status`` says if it stopped)."""
    bar = Bar(not args.no_progress)
    try:
        outcome = transfer.run(simulators, reality, args.transfer_trials, ea_of(args),
                               args.transfer_test_episodes, args.seed, ceiling(args), bar)
    except transfer.Stopped as stop:
        outcome = stop.outcome
    finally:
        bar.close()
    return transfer_stats.block(outcome)


def do_no_harm(block: dict, paths: dict[str, Path]) -> dict[str, Path]:
    """Rename the fitted params files when the diagnosed simulator is not recommended, and
    say so in diagnosis.json and report.md; returns the paths as they now are."""
    paths = dict(paths)
    renamed = [k for k in REJECTED if k in paths] if block.get('recommended') is False else []
    for key in renamed:
        name = REJECTED[key]
        target = paths[key].with_name(name)
        text = paths[key].read_text()
        atomic_write_text(target, f'# NOT RECOMMENDED: {block["recommendation"]}\n' + text)
        paths[key].unlink()
        paths[key] = target
    for key, name in REJECTED.items():        # an earlier run's verdict is not this one's
        stale = paths['diagnosis'].with_name(name)
        if key not in renamed and stale.exists():
            stale.unlink()
    data = json.loads(paths['diagnosis'].read_text())
    data['transfer'] = block
    data['recommended'] = block.get('recommended')
    data['recommendation'] = block.get('recommendation')
    write_json(paths['diagnosis'], data)
    report = paths.get('report')
    if report is not None:
        text = report.read_text()
        for key in renamed:                   # the report's file list names the new files
            name = REJECTED[key]
            text = text.replace(f'`{name.replace(".rejected", "")}`', f'`{name}`')
        head, _, rest = text.partition('\n')
        atomic_write_text(report, f'{head}\n\n**{transfer_report.recommendation_line(block)}**'
                                  f'\n{rest}\n{transfer_report.markdown(block)}')
    return paths
