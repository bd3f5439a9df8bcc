"""Run the replication over a map of emulated realities and chart where the claim holds.

Each point is one emulated reality: ``--shares`` of its ``--levels`` of sensor
noise shared within the groups of ``--groupings`` (the rest independent), with
the default robot's calibration, latency and wheels; plus the positive control,
reality = the simulator's combination model.  Steps 1-2 run once and are shared
by every point.  Output: the step-5 difference (combination - independent) with
its 95% CI per point (table and figure), a cross-test table (training noise
model x test world), and per point the drop at step 3 and what real training
recovers of it (with ``--ceiling``, also phase 2 at the full budget).  In process
only (``--backend core``); resumable.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import yaml

from .. import lifeline
from ..experiment import config as settings
from ..experiment import diagnosed, sweep
from ..experiment.protocol import Backends, Experiment, chunked, chunked_trace, play
from ..experiment.store import Store
from ..reality.khepera_robot import InProcessRobots, KheperaRobots
from ..reality.world import EmulatedWorld
from .replicate import Progress

SWEEP_ROBOTS = 200
STORE_KEYS = ('format', 'config_hash', 'condition', 'trial', 'step')    # the store's own
HELP = 'the replication over emulated realities (shared noise share, level, grouping)'


def _fractions(text: str) -> list[float]:
    try:
        return [float(v) for v in text.split(',') if v.strip()]
    except ValueError:
        raise ValueError(f'expected comma-separated fractions like 0,0.5,1, got {text!r}') \
            from None


def add_arguments(parser) -> None:
    parser.add_argument('--config', type=Path, metavar='YAML',
                        help='replication settings (see config/replicate.yaml)')
    parser.add_argument('--sweep', type=Path, metavar='YAML', dest='sweep_file',
                        help=f'sweep settings: a mapping with keys {", ".join(sweep.KEYS)}')
    parser.add_argument('--shares', help='shares of shared noise, e.g. 0,0.5,1 (default '
                        f"{','.join(map(str, sweep.DEFAULTS['shares']))})")
    parser.add_argument('--levels', help='total noise levels, e.g. 0.05,0.1 (default '
                        f"{','.join(map(str, sweep.DEFAULTS['levels']))})")
    parser.add_argument('--groupings', help=f'groupings of the shared noise, from '
                        f"{', '.join(sweep.GROUPINGS)} (default front)")
    parser.add_argument('--no-control', action='store_true',
                        help='leave out the control point (reality = the simulator)')
    parser.add_argument('--params', type=Path, metavar='FITTED_PARAMS',
                        help="a fitted_params.yaml (khepera-noise diagnose): its simulator "
                             "becomes a condition 'diagnosed' beside the paper's models")
    parser.add_argument('--port', action='append', metavar='DEV',
                        help='add a point whose reality is the robot on these serial ports '
                             '(repeatable, one robot per port; e.g. a foreign robot served '
                             'by benchmark/foreign_robots.py serve)')
    parser.add_argument('--no-emulated', action='store_true',
                        help='leave out the emulated realities (with --port: the robot only)')
    parser.add_argument('--trials', type=int, help='trials per condition (default 50)')
    parser.add_argument('--ceiling', action='store_true',
                        help='also run the ceiling arm at every point: phase 2 again with the '
                             'full budget (settings key ceiling); resumes a sweep without it')
    parser.add_argument('--seed', type=int, help="the run's seed (overrides the config)")
    parser.add_argument('--protocol', choices=sorted(settings.PROTOCOLS),
                        help='measurement protocol (default: the config\'s, measured)')
    parser.add_argument('--backend', choices=('core',), default='core',
                        help='the sweep runs in process only')
    parser.add_argument('--out', type=Path, default=Path('results/sweep'),
                        help='results directory')
    parser.add_argument('--fresh', action='store_true', help='discard earlier results')
    parser.add_argument('--no-progress', action='store_true', help='no progress bar')


def spec_from(args) -> dict:
    spec = settings.read_yaml(args.sweep_file) if args.sweep_file else {}
    for name in ('shares', 'levels'):
        if getattr(args, name) is not None:
            spec[name] = _fractions(getattr(args, name))
    if args.groupings is not None:
        spec['groupings'] = [g.strip() for g in args.groupings.split(',') if g.strip()]
    if args.no_control:
        spec['control'] = False
    if args.trials is not None:
        spec['trials'] = args.trials
    return sweep.check(spec)


def run(args) -> int:
    spec = spec_from(args)
    # larger batches of emulated robots: the same physics, fewer passes over the chunks
    overrides = {'trials': spec['trials'], 'reality': {'robots': SWEEP_ROBOTS},
                 'backend': {'simulation': 'core', 'reality': 'world'}}
    if args.seed is not None:
        overrides['seed'] = args.seed
    if getattr(args, 'ceiling', False):
        overrides['ceiling'] = {'enabled': True}
    if getattr(args, 'params', None) is not None:
        overrides['diagnosed'] = str(args.params)
    base = settings.load(args.config, overrides=overrides, protocol=args.protocol)
    ports = tuple(getattr(args, 'port', None) or ())
    pts = ([] if getattr(args, 'no_emulated', False) else sweep.points(spec)) + \
        ([sweep.Point(None, None, None, ports)] if ports else [])
    if not pts:
        raise ValueError('--no-emulated leaves no reality: add --port DEV')
    args.out.mkdir(parents=True, exist_ok=True)
    started, results = time.monotonic(), []
    with lifeline.terminate_as_interrupt():
        first = None
        for i, point in enumerate(pts):
            config = sweep.point_config(base, point)
            store = Store(args.out / 'points' / point.key, config.hash)
            store.open(config.to_yaml(), fresh=args.fresh)
            if first is not None:
                share_simulation(first, store, config)
            print(f'point {i + 1}/{len(pts)}: {point.label}', file=sys.stderr)
            with Progress(enabled=not args.no_progress) as progress:
                experiment = Experiment(config, backends(config, point), store, progress)
                progress.start(experiment.episodes_left(), {'simulation': 0.0005,
                                                            'reality': 0.004})
                experiment.run()
            first = first or store
            results.append((point, store, config))
    elapsed = time.monotonic() - started
    analysis = sweep.analyse(results)
    analysis.update({'settings': spec, 'seed': base.seed, 'protocol': base.data['protocol'],
                     'elapsed_s': elapsed})
    write(args.out, analysis)
    print(sweep.table(analysis), end='')
    print(sweep.diagnosed_table(analysis, 3), end='')
    print(f"wrote {args.out / 'sweep.md'} ({elapsed:.0f} s this session)")
    return 0


def share_simulation(source: Store, store: Store, config) -> None:
    """Steps 1-2 do not depend on reality: copy them from the first point."""
    for c in config.conditions:
        for t in range(config.trials):
            for step in (1, 2):
                unit = source.load(c.key, t, step)
                if unit is not None and store.load(c.key, t, step) is None:
                    store.save(c.key, t, step, {k: v for k, v in unit.items()
                                                if k not in STORE_KEYS})


def backends(config, point: sweep.Point) -> Backends:
    simulate = diagnosed.core(config)
    capacity = config.reality['robots']
    if point.ports:
        robots = KheperaRobots.on_ports(list(point.ports), config.world, config.task)
        n = len(point.ports)
        return Backends(simulate, chunked(lambda g, s: play(robots, g, s)[0], n),
                        chunked_trace(lambda g, s: play(robots, g, s)[1], n),
                        {'reality': point.label})
    if point.shared is None:
        control = sweep.control_reality(config)
        return Backends(simulate, chunked(control, capacity),
                        chunked_trace(lambda g, s: control(g, s, traced=True), capacity),
                        {'reality': point.label})
    world = EmulatedWorld(config.effects, seed=config.reality['seed'], robots=capacity,
                          geometry=config.world,
                          start_bearing_deg=config.reality['start_bearing_deg'])
    robots = KheperaRobots(InProcessRobots(world), config.world, config.task)
    return Backends(simulate, chunked(lambda g, s: play(robots, g, s)[0], capacity),
                    chunked_trace(lambda g, s: play(robots, g, s)[1], capacity),
                    {'reality': point.label})


def _diagnosed_md(analysis: dict) -> list[str]:
    table = sweep.diagnosed_table(analysis, 3)
    if not table:
        return []
    return ['## Does the diagnosed simulator transfer better? Diagnosed - each paper '
            "condition, Welch's 95% CI", '', 'Step 3 (first real test):', '', table,
            'Step 5 (after real training):', '', sweep.diagnosed_table(analysis, 5)]


def write(out: Path, analysis: dict) -> None:
    figure = sweep.figure(analysis, out / 'sweep_step5.png')
    text = ['# Sweep: where does modelling sensor dependence pay?', '',
            f"Seed {analysis['seed']}, protocol {analysis['protocol']}, "
            f"{analysis['settings']['trials']} trials per condition and point, "
            f"{analysis['elapsed_s']:.0f} s.", '',
            '## Step 5 (final real test): combination - independent, with Welch 95% CI', '',
            sweep.table(analysis), f'![step 5 differences]({figure.name})', '',
            '## Step 3 (first real test): combination - independent', '',
            sweep.table(analysis, step=3),
            '## Cross-test: training noise model x test world (mean step-3 score)', '',
            sweep.cross_table(analysis),
            '## The drop, and how much of it real training recovers (all conditions)', '',
            'Paired by trial (the same controllers on the same test episodes); the ceiling '
            'arm (`--ceiling`) is phase 2 again with the full budget. Where even the ceiling '
            'recovers nothing, no noise model can transfer better at step 5.', '',
            sweep.recovery_table(analysis), *_diagnosed_md(analysis), '## Settings', '',
            '```yaml',
            yaml.safe_dump(analysis['settings'], sort_keys=False).rstrip(), '```', '']
    (out / 'sweep.md').write_text('\n'.join(text))
    (out / 'sweep.json').write_text(json.dumps(analysis, indent=1, default=str))
