"""Sample a noise model for fixed base values, like the paper's Figures 1, 6 and 7.

With no options it draws the three figures: independent noise (Figure 1), and the
combination model with 8% independent + 2% dependent (Figure 6, low correlation)
and 2% + 8% (Figure 7, high correlation) on two sensors with base values 100 and 110.
Each writes a CSV of the time series and a PNG whose title gives the correlation of
the plotted samples and of a large sample.
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ..core.noise import NoiseModel, parse_groups

HELP = 'sample a noise model for fixed base values (paper Figures 1, 6, 7)'

# name: (title, model, dependent, independent, base values, paper's correlation)
PRESETS = {
    'fig1': ('Figure 1: independent noise', 'independent', 0.0, 0.076, (66, 66), -0.29),
    'fig6': ('Figure 6: 8% independent + 2% dependent', 'combination', 0.02, 0.08,
             (100, 110), 0.14),
    'fig7': ('Figure 7: 2% independent + 8% dependent', 'combination', 0.08, 0.02,
             (100, 110), 0.96),
}


def add_arguments(parser) -> None:
    parser.add_argument('--preset', choices=sorted(PRESETS), action='append',
                        help='a paper figure to draw (repeatable; default: all three)')
    parser.add_argument('--base', type=float, nargs='+', metavar='V',
                        help='custom base values (one per sensor); overrides --preset')
    parser.add_argument('--model', default='combination', choices=('independent', 'combination'))
    parser.add_argument('--dependent', type=float, default=0.02)
    parser.add_argument('--independent', type=float, default=0.08)
    parser.add_argument('--distribution', choices=('uniform', 'normal'), default='uniform')
    parser.add_argument('--samples', type=int, default=60,
                        help='length of the plotted time series (the paper: 1 per s for 60 s)')
    parser.add_argument('--large', type=int, default=200_000,
                        help='sample size for the large-sample correlation')
    parser.add_argument('--seed', type=int, default=1)
    parser.add_argument('--out', type=Path, default=Path('results/noise'))


def run(args) -> int:
    if args.samples < 3 or args.large < 3:
        raise ValueError(f'--samples and --large must be at least 3, got {args.samples} and '
                         f'{args.large}')
    if args.base:
        n = len(args.base)
        specs = {'custom': (f'{args.model} d={args.dependent:g} i={args.independent:g}',
                            args.model, args.dependent, args.independent, tuple(args.base),
                            None)}
        groups = parse_groups(','.join(str(i) for i in range(n)))
    else:
        specs = {k: PRESETS[k] for k in (args.preset or sorted(PRESETS))}
        groups = ((0, 1),)
    for name, (title, model, d, i, base, paper) in specs.items():
        noise = NoiseModel(model, d, i, groups, args.distribution)
        series = noise.sample(base, np.random.default_rng(args.seed), args.samples)
        big = noise.sample(base, np.random.default_rng(args.seed + 1), args.large)
        r_plot, r_big = _corr(series), _corr(big)
        csv_path = _write_csv(args.out / f'{name}.csv', series)
        png_path = _plot(args.out / f'{name}.png', series, title, r_plot, r_big, args.large)
        versus = f'; paper {paper:+.2f}' if paper is not None else ''
        print(f'{name}: correlation {r_plot:+.2f} over {args.samples} samples, '
              f'{r_big:+.3f} over {args.large}{versus}  -> {csv_path}, {png_path}')
    return 0


def _corr(x: np.ndarray) -> float:
    """Mean pairwise correlation of the columns (the one pair for two sensors)."""
    c = np.corrcoef(x.T)
    return float(c[np.triu_indices_from(c, 1)].mean())


def _write_csv(path: Path, series: np.ndarray) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, 'w', newline='') as f:
        w = csv.writer(f)
        w.writerow(['sample'] + [f's{i}' for i in range(series.shape[1])])
        for t, row in enumerate(series):
            w.writerow([t] + [int(v) if v == int(v) else v for v in row])
    return path


def _plot(path: Path, series, title: str, r_plot: float, r_big: float, large: int) -> Path:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.4, 3.2))
    for i in range(series.shape[1]):
        ax.plot(series[:, i], lw=1.2, label=f'sensor {i}')
    ax.set_title(f'{title}\ncorrelation {r_plot:+.0%} (plotted), {r_big:+.1%} '
                 f'({large} samples)', fontsize=9)
    ax.set_xlabel('sample')
    ax.set_ylabel('reading (0 = brightest)')
    ax.legend(fontsize=8, loc='upper right')
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
