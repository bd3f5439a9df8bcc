"""Run one test episode and plot the fitness at each step, like the paper's Figure 8.

The controller is a genome (from an evolve result or a JSON list) or, by
default, the hand-written baseline that turns toward the brighter side.  The
fitness drops every fifth step, when the heading is perturbed.
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ..core import baseline, network, task
from . import _options
from .evolve import load_genome

HELP = 'run a test episode and plot per-step fitness (paper Figure 8)'


def add_arguments(parser) -> None:
    parser.add_argument('--genome', type=Path, metavar='JSON',
                        help='controller genome (default: the hand-written baseline)')
    _options.add_noise_arguments(parser)
    _options.add_world_arguments(parser)
    parser.add_argument('--seed', type=int, default=0, help='episode seed')
    parser.add_argument('--out', type=Path, default=Path('results/episode'))


def run(args) -> int:
    if args.genome:
        weights = network.unpack(load_genome(args.genome))

        def policy(r):
            return network.act(weights, r)
        label = f'genome {args.genome.name}'
    else:
        policy, label = baseline.turn_toward_light, 'hand-written baseline'
    trace = task.run(policy, [args.seed], world=_options.world_from_args(args),
                     noise=_options.noise_from_args(args), trace=True)
    fitness = trace.fitness[:, 0]
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / 'episode.csv', 'w', newline='') as f:
        w = csv.writer(f)
        w.writerow(['step', 'bearing_deg'] + [f's{i}' for i in range(8)]
                   + ['direction', 'power', 'fitness'])
        for t in range(len(fitness)):
            w.writerow([t, trace.bearing_deg[t, 0], *trace.readings[t, 0].astype(int),
                        trace.direction[t, 0], trace.power[t, 0], f'{fitness[t]:.4f}'])
    plot_fitness(args.out / 'fig8.png', fitness, f'{label}: average fitness '
                 f'{fitness.mean():.3f} (paper Figure 8: 0.818)')
    print(f'average fitness {fitness.mean():.3f} over {len(fitness)} steps '
          f'-> {args.out}/episode.csv, {args.out}/fig8.png')
    return 0


def plot_fitness(path: Path, fitness: np.ndarray, title: str) -> Path:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.4, 3.0))
    ax.plot(np.arange(len(fitness)), fitness, lw=1.2, color='k')
    ax.set_ylim(0, 1)
    ax.set_xlabel('time step')
    ax.set_ylabel('fitness')
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
