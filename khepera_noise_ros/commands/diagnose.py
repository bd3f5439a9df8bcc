"""Diagnose the sim-to-real gap of real recordings: where it lies, which unmodelled effect
causes it, and how far adding that effect shrinks it on held-out data.

The recordings (CSV + YAML manifest, or rosbag2 directories) are reproduced in
the simulator of --params (its defaults without): the same headings and
conditions for stationary data, the same genome and number of episodes for
closed-loop data.  Writes OUT/diagnosis.json, OUT/report.md with figures, and,
when an effect explains the gap, OUT/fitted_params.yaml for the simulator node
(--ros-args --params-file).  With --transfer-emulator or --transfer-port and a
closed-loop recording, the transfer experiment is re-run with the fitted effect.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core import evolution
from ..effects import NAMES
from .. import simconfig
from ..experiment import diagnosis_report, transfer
from ..gap import diagnose
from ..gap.protocol import BASES, condition_world, kind
from ..recording import load

HELP = 'diagnose the sim-to-real gap of recordings; fit the unmodelled effect behind it'


def add_arguments(parser) -> None:
    parser.add_argument('recordings', nargs='+', type=Path, metavar='RECORDING',
                        help='NAME (NAME.csv + NAME.yaml) or a rosbag2 directory')
    parser.add_argument('--params', type=Path, metavar='YAML',
                        help="the simulator's params file (default: the simulator's defaults)")
    parser.add_argument('--out', type=Path, default=Path('results/diagnosis'))
    parser.add_argument('--hold-out', nargs='+', default=(), metavar='CONDITION',
                        help='fit on the other conditions, check on these (default: fit on '
                             'alternate episodes, check on the rest)')
    parser.add_argument('--base', choices=BASES, default='auto',
                        help="simulated light levels: the light model at the recorded headings "
                             "(model) or the recording's own means (observed)")
    parser.add_argument('--effects', nargs='+', choices=NAMES, default=NAMES,
                        help='candidate effects')
    parser.add_argument('--replicates', type=int, default=200, help='bootstrap replicates')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--no-figures', action='store_true')
    t = parser.add_argument_group('transfer experiment (closed-loop recordings)')
    t.add_argument('--transfer-emulator', metavar='EFFECTS_YAML',
                   help="reality is the emulated robot of this effects file ('real_robot' "
                        "for the emulator's default)")
    t.add_argument('--transfer-port', nargs='+', metavar='PORT',
                   help='reality is the Khepera(s) on these serial ports')
    t.add_argument('--transfer-trials', type=int, default=5)
    t.add_argument('--transfer-population', type=int, default=25)
    t.add_argument('--transfer-generations', type=int, default=50)


def run(args) -> int:
    if args.replicates < 20:
        raise ValueError(f'--replicates must be at least 20, got {args.replicates}')
    config = simconfig.load(args.params)
    recordings = [load(p) for p in args.recordings]
    for path, rec in zip(args.recordings, recordings):
        rec.manifest.setdefault('name', path.name)
    options = diagnose.Options(config=config, seed=args.seed, base=args.base,
                               held_out=tuple(args.hold_out), replicates=args.replicates,
                               effects=tuple(args.effects))
    reality = _reality(args, recordings, config)
    ea = evolution.EAConfig(population=args.transfer_population,
                            generations=args.transfer_generations)
    result = diagnose.diagnose(recordings, options)
    if result.fitted is not None and reality is not None and args.transfer_trials:
        loop = next(r for r in recordings if kind(r) == 'closed_loop')
        label = loop.conditions()[0]
        result.transfer = transfer.run(config, condition_world(loop, label, config.world),
                                       [result.fitted], reality, args.transfer_trials,
                                       ea=ea, seed=args.seed)
        result.transfer['condition'] = label
    paths = diagnosis_report.write(result, args.out, config, figures=not args.no_figures)
    _print(result, paths)
    return 0


def _print(result: diagnose.Diagnosis, paths: dict) -> None:
    print(f'top effect: {result.top_effect}')
    for note in result.notes:
        print(f'  {note}')
    for e in result.where[:5]:
        print(f"  where: {e['statistic']} {e['sensors']} {e['condition'] or ''} "
              f"{e['part'] or ''}: simulated {e['sim']:.4g}, real {e['real']:.4g} "
              f"(z {e['significance']:.1f})")
    for e in result.effects:
        print(f"  {e['name']:26s} held-out reduction {e['heldout_reduction']:6.2f} "
              f"{e['sensors'] or ''}")
    if result.compound is not None:
        steps = ', '.join(f"{c['name']} ({c['cumulative_reduction']:.2f})"
                          for c in result.compound.steps)
        print(f'  compound (cumulative held-out reduction): {steps}')
    rem = result.remainder or {}
    if 'heldout_reduction_with_empirical' in rem:
        print(f"  remainder: {rem['statistics_off']} statistics still off; named effects "
              f"{rem['heldout_reduction_named']:.2f}, with the empirical model "
              f"{rem['heldout_reduction_with_empirical']:.2f}")
    if result.transfer:
        t = result.transfer
        print(f"  transfer: fitness gap {t['fitness_gap_before']:.3f} -> "
              f"{t['fitness_gap_after']:.3f} (Welch p = {t['gap_p']})")
    for what, path in paths.items():
        print(f'wrote {what}: {path}')


def _reality(args, recordings, config):
    """The black box the transfer experiment tests in, or None."""
    if not (args.transfer_emulator or args.transfer_port):
        return None
    if args.transfer_emulator and args.transfer_port:
        raise ValueError('choose one of --transfer-emulator and --transfer-port')
    loops = [r for r in recordings if kind(r) == 'closed_loop']
    if not loops:
        raise ValueError('the transfer experiment needs a closed-loop recording')
    world = condition_world(loops[0], loops[0].conditions()[0], config.world)
    if args.transfer_port:
        return port_reality(args.transfer_port, world, config)
    return emulator_reality(args.transfer_emulator, world, config, args.seed)


def emulator_reality(effects: str, world, config: simconfig.SimConfig, seed: int):
    """(genomes, seeds) -> fitness on emulated robots, one per genome."""
    from ..reality.effects import EffectsConfig
    from ..reality.khepera_robot import InProcessRobots, KheperaRobots
    from ..reality.world import EmulatedWorld
    physics = EffectsConfig.real_robot() if effects == 'real_robot' \
        else EffectsConfig.load(effects)

    def evaluate(genomes, seeds):
        env = KheperaRobots(InProcessRobots(EmulatedWorld(physics, seed, len(seeds))), world,
                            config.task)
        try:
            return transfer.fitness(env, genomes, seeds)
        finally:
            env.close()
    return evaluate


def port_reality(ports, world, config: simconfig.SimConfig):
    """(genomes, seeds) -> fitness on Kheperas on serial ports, as many at a time as ports."""
    from ..reality.khepera_robot import KheperaRobots
    env = KheperaRobots.on_ports(list(ports), world, config.task)

    def evaluate(genomes, seeds):
        out = []
        for lo in range(0, len(seeds), len(ports)):
            out.append(transfer.fitness(env, genomes[lo:lo + len(ports)],
                                        seeds[lo:lo + len(ports)]))
        return np.concatenate(out)
    return evaluate
