"""Diagnose the sim-to-real gap of real recordings: where it lies, which unmodelled effect
causes it, and how far adding that effect shrinks it on held-out data.

The recordings (CSV + YAML manifest, or rosbag2 directories) are reproduced in
the simulator of --params (its defaults without): the same headings and
conditions for stationary data, the same genome and number of episodes for
closed-loop data.  Writes OUT/diagnosis.json, OUT/report.md with figures, and,
when an effect explains the gap, OUT/fitted_params.yaml for the simulator node
(--ros-args --params-file).  With --transfer-emulator or --transfer-port and a
closed-loop recording, the transfer experiment (docs/transfer.md) evolves controllers in
the stock simulator, under the paper's two noise models and in the diagnosed simulator
(and, with --transfer-ceiling, on the robot itself), and tests every best on the robot.
Do no harm: when the diagnosed simulator's controllers do worse there, its params are
written as fitted_params.rejected.yaml instead.
"""
from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

from ..effects import DEFAULT
from .. import simconfig
from ..experiment import transfer, transfer_report
from ..experiment import diagnosis_report as report
from ..gap import diagnose
from ..gap.protocol import BASES, condition_world
from ..recording import load
from . import _transfer

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
    parser.add_argument('--effects', nargs='+', choices=DEFAULT, default=DEFAULT,
                        help='candidate effects')
    parser.add_argument('--replicates', type=int, default=200, help='bootstrap replicates')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--no-figures', action='store_true')
    _transfer.add_arguments(parser)


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
    if not _transfer.wanted(args):
        result = diagnose.diagnose(recordings, options)
        _print(result, report.write(result, args.out, config, figures=not args.no_figures))
        return 0
    loop = _transfer.closed_loop(recordings)
    label = loop.conditions()[0]
    world = condition_world(loop, label, config.world)
    with _transfer.robot(args, world, config) as (reality, where):    # a bad port fails now
        result = diagnose.diagnose(recordings, options)
        # the diagnosis is on disk before the robot is asked for anything
        paths = report.write(result, args.out, config, figures=False)
        if not result.fitted_effects:
            print('transfer experiment skipped: no effect was fitted', file=sys.stderr)
            _print(result, report.write(result, args.out, config, figures=not args.no_figures))
            return 0
        fitted = simconfig.load(paths['params'])          # the diagnosed simulator, as written
        simulators = transfer.arms(
            dataclasses.replace(config, world=world),
            dataclasses.replace(fitted, world=condition_world(loop, label, fitted.world)))
        print(f"transfer experiment on {where}: arms {', '.join(simulators)}"
              f"{', robot_trained' if _transfer.ceiling(args) else ''}", file=sys.stderr)
        block = {**_transfer.run(args, simulators, reality), 'condition': label,
                 'robot': where}
    # gap's report shows the kept keys of a finished comparison; the whole block goes in below
    result.transfer = block if block['fitness_gap_after'] is not None else None
    paths = _transfer.do_no_harm(block, report.write(result, args.out, config,
                                                     figures=not args.no_figures))
    result.transfer = block
    _print(result, paths)
    if block['status'] != 'complete':
        print(f"khepera-noise diagnose: error: {block['error']}; stopped while "
              f"{block['stopped_at']}; {block['done']}; partial results in "
              f"{paths['diagnosis']}", file=sys.stderr)
        return 130 if block['error'] == 'interrupted' else 1
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
        for line in transfer_report.lines(result.transfer):
            print(line)
    for what, path in paths.items():
        print(f'wrote {what}: {path}')
