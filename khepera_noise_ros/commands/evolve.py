"""Evolve light-centring controllers in the core simulator (the paper's phase 1).

Runs one or more independent trials of the steady-state tournament EA, all
evaluated as one batch, shows progress per generation, and writes a JSON file
with the settings, the best fitness per generation and each trial's best genome.
The same --seed gives the same result.  Use --seed-genome for a seeded start
(the paper's phase 2 starts from phase 1's best).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from ..core import evolution
from ..core.evaluation import CoreEvaluator
from ..core.noise import format_groups
from ..core.task import Task
from ..files import write_json
from . import _options

HELP = "evolve controllers in the core simulator (the paper's phase 1)"


def add_arguments(parser) -> None:
    _options.add_noise_arguments(parser)
    _options.add_world_arguments(parser)
    g = parser.add_argument_group('evolution')
    g.add_argument('--population', type=int, default=25)
    g.add_argument('--generations', type=int, default=50)
    g.add_argument('--trials', type=int, default=1, help='independent runs, evaluated together')
    g.add_argument('--fitness', choices=evolution.FITNESS_MODES, default='stored',
                   help='stored: evaluate once at birth; reevaluate: afresh in every tournament')
    g.add_argument('--best', choices=evolution.BEST_MODES, default='ever',
                   help='how the best individual is chosen')
    g.add_argument('--seed-genome', type=Path, metavar='JSON',
                   help="start from this genome (a list of 20, or an evolve result's best)")
    g.add_argument('--steps', type=int, default=Task.steps, help='steps per episode')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--out', type=Path, default=Path('results/evolve.json'))
    parser.add_argument('--quiet', action='store_true', help='no progress bar')


def load_genome(path: Path) -> np.ndarray:
    """A genome from a JSON list, or the first trial's best in an evolve result."""
    try:
        data = json.loads(Path(path).read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f'{path}: not JSON ({exc})') from None
    if isinstance(data, dict):
        data = data.get('best_genome') or data.get('trials', [{}])[0].get('best_genome')
    if data is None:
        raise ValueError(f"{path}: no genome found (expected a list of 20 numbers or an "
                         f"evolve result with 'trials[0].best_genome')")
    return np.asarray(data, dtype=float)


def run(args) -> int:
    noise = _options.noise_from_args(args)
    config = evolution.EAConfig(population=args.population, generations=args.generations,
                                fitness=args.fitness, best=args.best)
    if args.trials < 1:
        raise ValueError(f'--trials must be at least 1, got {args.trials}')
    evaluate = CoreEvaluator(_options.world_from_args(args), noise, Task(steps=args.steps))
    seed_genome = load_genome(args.seed_genome) if args.seed_genome else None
    # trial k uses seed + k, as the evolution_manager node does: the same --seed gives the
    # same trials in process and through the graph
    eas = [evolution.SteadyStateEA(config, args.seed + k, seed_genome)
           for k in range(args.trials)]
    try:
        evolution.evolve(eas, evaluate, progress=_progress_bar(eas, args.quiet))
    except KeyboardInterrupt:       # Ctrl-C or kill: keep the generations finished so far
        if all(ea.history for ea in eas):
            partial = write_json(args.out.with_suffix('.partial.json'),
                                 _result(args, noise, config, eas) | {'interrupted': True})
            print(f'stopped; the generations finished so far are in {partial}', file=sys.stderr)
        raise
    write_json(args.out, _result(args, noise, config, eas))
    for k, ea in enumerate(eas):
        print(f'trial {k}: best fitness {ea.best_fitness:.3f} at generation '
              f'{ea.best_generation} ({ea.evaluations} evaluations)')
    print(f'wrote {args.out}')
    return 0


def _progress_bar(eas, quiet: bool):
    from tqdm import tqdm
    bar = tqdm(total=eas[0].config.generations, unit='gen', disable=quiet, desc='phase')

    def update(eas):
        gen = min(len(ea.history) - 1 for ea in eas)
        if gen > bar.n:
            bar.update(gen - bar.n)
            bar.set_postfix(best=f'{max(ea.history[-1].best for ea in eas):.3f}')
        if all(ea.done for ea in eas):
            bar.close()
    return update


def _result(args, noise, config, eas) -> dict:
    return {
        'format': 'khepera-noise-evolve/1',
        'seed': args.seed,
        'noise': {'model': noise.model, 'dependent': noise.dependent,
                  'independent': noise.independent, 'groups': format_groups(noise.groups),
                  'distribution': noise.distribution},
        'world': {'lamp_distance_mm': args.lamp_distance, 'deg_per_power': args.deg_per_power},
        'steps': args.steps,
        'ea': vars(config),
        'trials': [{
            'best_fitness': ea.best_fitness, 'best_generation': ea.best_generation,
            'best_genome': ea.best_genome, 'evaluations': ea.evaluations,
            'history': [vars(h) for h in ea.history]} for ea in eas],
    }
