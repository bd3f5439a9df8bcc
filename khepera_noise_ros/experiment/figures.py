"""The paper's Figures 8-10 from our results, plus the evolution curves behind them.

Figures 9 and 10 keep the paper's colours (black = combination, white =
independent) and add what the paper's bars lack: 95% confidence intervals,
and the paper's own final values (Table 1) as markers at step 5.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .stats import Summary  # noqa: E402

STEP_LABELS = ('1\ntrain sim', '2\ntest sim', '3\ntest real', '4\ntrain real', '5\ntest real')
FACE = {'combination': 'black', 'independent': 'white'}
PAPER_MARKER = {'marker': 'D', 'color': 'tab:red', 'markeredgecolor': 'black'}


def steps(path: Path, level: str, summaries: dict[str, list[Summary]],
          paper_final: dict[str, float], figure: str) -> Path:
    """Bars of mean performance per step for each model, with 95% CI error bars.

    ``summaries``: model -> one Summary per step 1-5; ``paper_final``: model ->
    the paper's Table 1 value, drawn at step 5.
    """
    fig, ax = plt.subplots(figsize=(7, 4))
    x = np.arange(len(STEP_LABELS))
    width = 0.38
    for k, (model, rows) in enumerate(summaries.items()):
        means = np.array([s.mean for s in rows])
        err = np.array([[s.mean - s.ci_low, s.ci_high - s.mean] for s in rows]).T
        pos = x + (k - 0.5) * width
        ax.bar(pos, means, width, yerr=np.nan_to_num(err), capsize=3, color=FACE.get(model),
               edgecolor='black', label=f'{level} {model} (ours, n={rows[0].n})')
        if model in paper_final:
            ax.plot(pos[-1], paper_final[model], ls='none', **PAPER_MARKER)
    if paper_final:
        ax.plot([], [], ls='none', label="paper's final value (Table 1)", **PAPER_MARKER)
    lows = [s.ci_low if np.isfinite(s.ci_low) else s.mean for rows in summaries.values()
            for s in rows]
    ax.set_ylim(max(0.0, min(lows + list(paper_final.values())) - 0.05), 1.0)
    ax.set_xticks(x, STEP_LABELS)
    ax.set_ylabel('fitness (mean over trials, 95% CI)')
    ax.set_title(f'{figure}: training and testing performance at {level} noise', pad=28)
    ax.legend(loc='lower center', bbox_to_anchor=(0.5, 1.0), ncol=3, fontsize=8,
              frameon=False)
    return _save(fig, path)


def trace(path: Path, fitness, perturb_every: int, paper_mean: float | None,
          title: str) -> Path:
    """Figure 8: fitness at each step of one test episode."""
    fitness = np.asarray(fitness, dtype=float)
    fig, ax = plt.subplots(figsize=(7, 3.5))
    steps_ = np.arange(fitness.size)
    ax.plot(steps_, fitness, color='black', lw=1.2, marker='.', label='fitness per step')
    ax.axhline(fitness.mean(), color='tab:blue', ls='--',
               label=f'ours: average {fitness.mean():.3f}')
    if paper_mean is not None:
        ax.axhline(paper_mean, color='tab:red', ls=':', label=f'paper: average {paper_mean:.3f}')
    for s in range(0, fitness.size, perturb_every):
        ax.axvline(s, color='0.85', lw=0.8, zorder=0)
    ax.set_xlabel(f'time step (grey lines: heading perturbed, every {perturb_every} steps)')
    ax.set_ylabel('fitness')
    ax.set_ylim(0, 1)
    ax.set_title(title)
    ax.legend(loc='lower right', fontsize=8)
    return _save(fig, path)


def curves(path: Path, histories: dict[str, dict[int, np.ndarray]]) -> Path:
    """Best and mean population fitness per generation, averaged over trials.

    ``histories``: condition name -> {1: (trials, generations+1, 2) best/mean
    of phase 1, 4: the same for phase 2}.
    """
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    colours = plt.rcParams['axes.prop_cycle'].by_key()['color']
    for (name, phases), colour in zip(histories.items(), colours):
        for ax, step in zip(axes, (1, 4)):
            h = phases[step].mean(axis=0)
            ax.plot(h[:, 0], color=colour, label=f'{name} best')
            ax.plot(h[:, 1], color=colour, ls='--', label=f'{name} mean')
    axes[0].set_title('phase 1: evolution in simulation (step 1)')
    axes[1].set_title('phase 2: evolution in reality (step 4)')
    for ax in axes:
        ax.set_xlabel('generation')
    axes[0].set_ylabel('fitness (average over trials)')
    axes[1].legend(fontsize=7, loc='lower right')
    return _save(fig, path)


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
