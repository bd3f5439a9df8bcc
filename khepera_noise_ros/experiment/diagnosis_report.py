"""The diagnosis written out: diagnosis.json, report.md with its figures, fitted_params.yaml."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..files import atomic_write_text, write_json
from .. import simconfig
from ..gap.diagnose import Diagnosis
from ..effects.base import Key
from ..gap.compare import MARGIN, Comparison

FIGURES = ('correlation.png', 'spread.png', 'shrink.png', 'effects.png')


def write(diagnosis: Diagnosis, out: str | Path, config: simconfig.SimConfig,
          figures: bool = True) -> dict[str, Path]:
    """Write every output into directory ``out``; returns {what: path}."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {'diagnosis': write_json(out / 'diagnosis.json', diagnosis.to_json())}
    config = diagnosis.simulator(config)     # with the rounding the diagnosis chose
    fitted = diagnosis.fitted_effects
    if fitted:
        names = ', '.join(e.name for e in fitted)
        paths['params'] = simconfig.write(
            config.with_effects(*fitted), out / 'fitted_params.yaml',
            header=f'khepera-noise diagnose: the simulator with the fitted {names}\n'
                   f'load with: --ros-args --params-file fitted_params.yaml')
    if diagnosis.empirical is not None:
        paths['params_with_remainder'] = simconfig.write(
            config.with_effects(*fitted, diagnosis.empirical),
            out / 'fitted_params_with_remainder.yaml',
            header='khepera-noise diagnose: the fitted effects plus the empirical model of '
                   'what they leave\nload with: --ros-args --params-file '
                   'fitted_params_with_remainder.yaml')
    drawn = draw(diagnosis, out) if figures else {}
    paths.update(drawn)
    paths['report'] = atomic_write_text(out / 'report.md', markdown(diagnosis, drawn, paths))
    return paths


# --- figures ---------------------------------------------------------------------------

def draw(d: Diagnosis, out: Path) -> dict[str, Path]:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    drawn = {}
    for name, painter in (('correlation', _correlation), ('spread', _spread),
                          ('shrink', _shrink), ('effects', _effects),
                          ('waterfall', _waterfall), ('allan', _allan)):
        fig = painter(d, plt)
        if fig is not None:
            path = out / f'{name}.png'
            fig.savefig(path, dpi=110, bbox_inches='tight')
            plt.close(fig)
            drawn[name] = path
    return drawn


def _family(c: Comparison, family: str) -> list[tuple[Key, float, float]]:
    return [(k, r, s) for k, r, s in zip(c.keys, c.real, c.sim) if k.family == family]


def _correlation(d: Diagnosis, plt: Any) -> Any:
    rows = _family(d.full, 'correlation')
    if not rows:
        return None
    conditions = list(dict.fromkeys(k.condition for k, *_ in rows))[:4]
    sensors = sorted({s for k, *_ in rows for s in k.sensors})
    fig, axes = plt.subplots(len(conditions), 2, figsize=(6.4, 3.0 * len(conditions)),
                             squeeze=False)
    for i, cond in enumerate(conditions):
        for j, side in enumerate(('real', 'simulated')):
            m = np.eye(len(sensors))
            for k, r, s in rows:
                if k.condition == cond:
                    a, b = (sensors.index(x) for x in k.sensors)
                    m[a, b] = m[b, a] = r if j == 0 else s
            ax = axes[i, j]
            image = ax.imshow(m, vmin=-1, vmax=1, cmap='RdBu_r')
            ax.set_title(f'{side}: {cond}', fontsize=9)
            ax.set_xticks(range(len(sensors)), [f's{x}' for x in sensors], fontsize=7)
            ax.set_yticks(range(len(sensors)), [f's{x}' for x in sensors], fontsize=7)
    fig.colorbar(image, ax=axes, shrink=0.6, label='correlation of residuals')
    return fig


def _spread(d: Diagnosis, plt: Any) -> Any:
    level = {(k.sensors, k.condition, k.part): (r, s) for k, r, s in _family(d.full, 'level')}
    points = [(level[(k.sensors, k.condition, k.part)], (r, s))
              for k, r, s in _family(d.full, 'spread')
              if (k.sensors, k.condition, k.part) in level]
    if not points:
        return None
    (lr, ls), (sr, ss) = (np.array(v).T for v in zip(*points))
    fig, ax = plt.subplots(figsize=(5.5, 4))
    ax.scatter(ls, ss, s=10, alpha=0.6, label='simulated')
    ax.scatter(lr, sr, s=10, alpha=0.6, marker='x', label='real')
    ax.set_xlabel('light level (reading; 0 bright, 525 dark)')
    ax.set_ylabel('spread (sd of readings about the run mean)')
    ax.set_title('Spread against light level, every sensor and cell')
    ax.legend()
    return fig


def _family_discrepancy(c: Comparison) -> dict[str, float]:
    out: dict[str, float] = {}
    for k, z in zip(c.keys, c.z):
        out[k.family] = out.get(k.family, 0.0) + max(abs(z) - MARGIN, 0.0) ** 2
    return out


def _shrink(d: Diagnosis, plt: Any) -> Any:
    if d.held_out_before is None or d.held_out_after is None:
        return None
    before, after = _family_discrepancy(d.held_out_before), \
        _family_discrepancy(d.held_out_after)
    families = [f for f in sorted(before, key=lambda f: -before[f]) if before[f] > 0][:10]
    if not families:
        return None
    x = np.arange(len(families))
    fig, ax = plt.subplots(figsize=(7, 3.6))
    ax.bar(x - 0.2, [before[f] for f in families], 0.4, label='simulator as configured')
    ax.bar(x + 0.2, [after.get(f, 0.0) for f in families], 0.4,
           label=f'with {d.top_effect}')
    ax.set_yscale('symlog')
    ax.set_xticks(x, families, rotation=35, ha='right', fontsize=8)
    ax.set_ylabel('held-out discrepancy')
    ax.set_title('Before and after the fitted effect, on held-out data')
    ax.legend(fontsize=8)
    return fig


def _effects(d: Diagnosis, plt: Any) -> Any:
    if not d.effects:
        return None
    names = [e['name'] for e in d.effects]
    values = [max(e['heldout_reduction'], -1.0) for e in d.effects]
    fig, ax = plt.subplots(figsize=(6, 3.2))
    ax.barh(names[::-1], values[::-1])
    ax.axvline(0.25, color='grey', linestyle=':', label='needed to count')
    ax.set_xlim(-1, 1)
    ax.set_xlabel('share of the held-out discrepancy removed')
    ax.legend(fontsize=8)
    return fig


def _waterfall(d: Diagnosis, plt: Any) -> Any:
    if d.compound is None:
        return None
    steps = d.compound.steps
    names = [s['name'] for s in steps]
    added = [s['added_reduction'] for s in steps]
    bottom = [s['cumulative_reduction'] - s['added_reduction'] for s in steps]
    rem = d.remainder or {}
    if 'heldout_reduction_with_empirical' in rem:
        names.append('empirical remainder')
        added.append(rem['heldout_reduction_with_empirical'] - rem['heldout_reduction_named'])
        bottom.append(rem['heldout_reduction_named'])
    fig, ax = plt.subplots(figsize=(6.4, 3.4))
    colours = ['C0'] * len(steps) + ['C7'] * (len(names) - len(steps))
    ax.bar(range(len(names)), added, bottom=bottom, color=colours)
    for i, (a, b) in enumerate(zip(added, bottom)):
        ax.text(i, a + b + 0.01, f'{a + b:.2f}', ha='center', fontsize=8)
    ax.set_xticks(range(len(names)), names, rotation=25, ha='right', fontsize=8)
    ax.set_ylim(min(0.0, min(bottom)), 1.05)
    ax.set_ylabel('held-out discrepancy removed (cumulative)')
    ax.set_title('Compound diagnosis: effects in the order chosen')
    return fig


def _allan(d: Diagnosis, plt: Any) -> Any:
    a = d.allan
    if not a:
        return None
    fig, ax = plt.subplots(figsize=(6, 4))
    t = a['taus']
    for k, (sensor, dev) in enumerate(a['real']['sensors'].items()):
        ax.loglog(t, dev, color='C0', alpha=0.35, lw=1, label='real, per sensor' if k == 0
                  else None)
        sim = a['simulated']['sensors'].get(sensor)
        if sim:
            ax.loglog(t, sim, color='C1', alpha=0.35, lw=1, ls='--',
                      label='simulated, per sensor' if k == 0 else None)
    ax.loglog(t, a['real']['shared'], color='C0', lw=2.5, label='real, shared component')
    ax.loglog(t, a['simulated']['shared'], color='C1', lw=2.5, ls='--',
              label='simulated, shared component')
    ax.set_xlabel('averaging time (samples)')
    ax.set_ylabel('Allan deviation (reading units)')
    ax.set_title('Fast against slow: slope -1/2 white, 0 flicker, +1/2 walk, +1 drift',
                 fontsize=9)
    ax.legend(fontsize=7)
    return fig


# --- markdown --------------------------------------------------------------------------

def markdown(d: Diagnosis, drawn: dict[str, Path], paths: dict[str, Path]) -> str:
    lines = ['# Sim-to-real gap diagnosis', '', f'**Top effect: `{d.top_effect}`**', '']
    lines += [f'- {n}' for n in d.notes] + ([''] if d.notes else [])
    lines += ['## Inputs', '']
    for i, rec in enumerate(d.inputs):
        lines.append(f"- recording {i + 1}: {rec['protocol']}, {rec['samples']} samples in "
                     f"{rec['episodes']} episodes, conditions {', '.join(rec['conditions'])}, "
                     f"{rec['channels']} channels (using {rec['channels_used']})")
    lines += ['', '## 1. Where the gap lies', '',
              'Largest standardised differences (z = difference / bootstrap standard error; '
              'p Holm-adjusted over all statistics):', '',
              '| statistic | sensors | condition | part | simulated | real | z | p |',
              '| --- | --- | --- | --- | --- | --- | --- | --- |']
    for e in d.where[:15]:
        lines.append(f"| {e['statistic']} | {_sensors(e['sensors'])} | {e['condition'] or ''} "
                     f"| {e['part'] or ''} | {e['sim']:.4g} | {e['real']:.4g} | "
                     f"{e['significance']:.1f} | {e['p_value']:.2g} |")
    loc = d.localisation
    if loc.get('families'):
        lines += ['', 'Share of the significant discrepancy by ' + '; '.join(
            f"{what}: " + ', '.join(f'{k} {v:.0%}' for k, v in list(loc[what].items())[:6])
            for what in ('families', 'sensors', 'pairs', 'conditions', 'parts') if loc[what])]
    lines += ['', '## 2. Which effect', '',
              '| effect | sensors | held-out reduction | 95% interval | p | parameters | '
              'how located |', '| --- | --- | --- | --- | --- | --- | --- |']
    for e in d.effects:
        lo, hi = e['reduction_interval']
        lines.append(f"| {e['name']} | {_sensors(e['sensors'])} | "
                     f"{e['heldout_reduction']:.2f} | [{lo:.2f}, {hi:.2f}] | "
                     f"{e['p_value']:.3f} | {_params(e['parameters'])} | {e['note']} |")
    lines += ['', '## 3. How far it shrinks', '']
    if d.fitted is not None:
        top = d.effects[0]
        lines.append(f"On held-out data the discrepancy goes from "
                     f"{top['discrepancy_before']:.1f} to {top['discrepancy_after']:.1f} "
                     f"({top['heldout_reduction']:.0%} removed).")
        if d.combined:
            c = d.combined
            lines.append(f"With {' and '.join(c['effects'])} together: "
                         f"{c['discrepancy_after']:.1f} ({c['heldout_reduction']:.0%} "
                         f"removed).")
    else:
        lines.append('No effect was added.')
    if d.compound is not None:
        lines += ['', '### Compound (forward selection, each effect fitted jointly with those '
                      'before it)', '', '| step | effect | sensors | added shrink | cumulative | '
                  'p | parameters |', '| --- | --- | --- | --- | --- | --- | --- |']
        for i, c in enumerate(d.compound.steps):
            lines.append(f"| {i + 1} | {c['name']} | {_sensors(c['sensors'])} | "
                         f"{c['added_reduction']:.3f} | {c['cumulative_reduction']:.3f} | "
                         f"{c['p_value']:.3f} | {_params(c['parameters'])} |")
        for r in d.compound.rejected:
            lines.append(f"\nNext best, not kept: {r['name']} (added {r['added_reduction']:.3f}"
                         f", p = {r['p_value']:.3f}).")
    if d.remainder:
        r = d.remainder
        lines += ['', '### What is left', '',
                  f"After {', '.join(r['named_effects']) or 'no named effect'}: "
                  f"{r['statistics_off']} statistics still differ significantly; "
                  f"{r['share_of_gap_left']:.0%} of the held-out discrepancy is left."]
        if 'heldout_reduction_with_empirical' in r:
            lines.append(f"Named effects remove {r['heldout_reduction_named']:.0%}; with the "
                         f"empirical remainder model {r['heldout_reduction_with_empirical']:.0%}"
                         f" (fitted_params_with_remainder.yaml).")
        for e in r['where'][:8]:
            lines.append(f"- {e['statistic']} {_sensors(e['sensors'])} {e['condition'] or ''} "
                         f"{e['part'] or ''}: simulated {e['sim']:.4g}, real {e['real']:.4g} "
                         f"(z {e['significance']:.1f})")
    if d.allan:
        sh = d.allan.get('shared', {})
        if sh:
            lines += ['', f"Allan deviation of the shared component: real {sh['real_term']}, "
                          f"simulated {sh['simulated_term']} at the longest averaging times; "
                          f"real/simulated {sh['long_ratio'] or float('nan'):.2f} there, "
                          f"{sh['short_ratio'] or float('nan'):.2f} at one sample."]
    if d.transfer:
        t = d.transfer
        p = 'n/a' if t['gap_p'] is None else f"{t['gap_p']:.3g}"
        lines += ['', f"Transfer experiment ({t['trials']} trials per arm, "
                      f"{t['test_episodes']} test episodes each, condition {t['condition']}): "
                      f"fitness gap (simulated minus real) {t['fitness_gap_before']:.3f} "
                      f"before, {t['fitness_gap_after']:.3f} after ({t['test']}, p = {p}); "
                      f"real fitness {t['real_fitness_before']:.3f} -> "
                      f"{t['real_fitness_after']:.3f}."]
    lines += ['', '## Figures', '']
    for name, path in drawn.items():
        lines.append(f'![{name}]({Path(path).name})')
    lines += ['', '## Files', ''] + [f'- {k}: `{Path(v).name}`' for k, v in paths.items()]
    return '\n'.join(lines) + '\n'


def _sensors(sensors: Sequence[int]) -> str:
    return ' '.join(f's{s}' for s in sensors)


def _params(params: dict[str, Any]) -> str:
    def short(v: Any) -> str:
        if isinstance(v, float):
            return f'{v:.4g}'
        if isinstance(v, list):
            return '[' + ', '.join(short(x) for x in v) + ']'
        return str(v)
    return ', '.join(f'{k}={short(v)}' for k, v in params.items())
