"""Where does the paper's claim hold?  The experiment over a map of emulated realities.

Each sweep point is one emulated reality.  Its sensor noise is ``level`` in
all, of which a fraction ``shared`` is one draw shared by each group of
``grouping`` (the emulator's ``correlated_noise``) and the rest each sensor's
own (``sensor_noise``); the room's flicker and drift are off, so the swept noise
is the only noise, and the rest of the default robot (its calibration, latency
and wheels) stays, so every point keeps a sim-to-real gap.  The point
``control`` is reality = the simulator with its own combination model at the
first level: the positive control, where modelling the dependence must pay.

Steps 1-2 do not depend on reality, so they run once (in the first point's
store) and every other point starts from copies of them.  Every point is a
results store of its own and resumes like ``replicate``.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from ..core import task
from ..reality.effects import EffectsConfig
from .config import ReplicateConfig, build

GROUPINGS = {
    'front': [[0, 1, 2, 3, 4, 5], [6, 7]],      # the simulator's default dependence groups
    'halves': [[0, 1, 2], [3, 4, 5], [6, 7]],   # each side of the front arc, the back pair
    'pairs': [[0, 1], [2, 3], [4, 5], [6, 7]],  # adjacent pairs
}
KEYS = ('shares', 'levels', 'groupings', 'control', 'trials')
DEFAULTS = {'shares': [0.0, 0.5, 1.0], 'levels': [0.05, 0.10], 'groupings': ['front'],
            'control': True, 'trials': 50}
CONTROL = 'control'
ROBOT = 'robot'
# the control's reality draws its noise from other streams than the simulation tests
CONTROL_SALT = 0x5DEECE66D


@dataclass(frozen=True)
class Point:
    """One emulated reality of the sweep."""

    shared: float | None        # None for the control and the robot
    level: float | None
    grouping: str | None
    ports: tuple[str, ...] = ()     # the robot on these serial ports is reality

    @property
    def key(self) -> str:
        if self.ports:
            return ROBOT
        if self.shared is None:
            return CONTROL
        return f'share{self.shared:g}-level{self.level:g}-{self.grouping}'

    @property
    def label(self) -> str:
        if self.ports:
            return f"the robot on {', '.join(self.ports)}"
        if self.shared is None:
            return 'control: reality = simulator (combination)'
        return f'{self.shared:.0%} shared of {self.level:.0%} ({self.grouping})'

    def effects(self, base: EffectsConfig) -> EffectsConfig:
        """The emulated robot of this point: ``base`` with its noise replaced."""
        groups = GROUPINGS[self.grouping]
        # correlated_noise is normal with sd strength x mean; a uniform part of level p
        # has sd p/sqrt(3), so this gives the shared part the spread getnoise would
        return base.replace(
            sensor_noise=self.level * (1.0 - self.shared),
            correlated_noise={'enabled': self.shared > 0, 'location': groups,
                              'strength': self.level * self.shared / math.sqrt(3.0)},
            intensity_dependent_noise={'enabled': False}, temporal_drift={'enabled': False})


def check(spec: dict) -> dict:
    """The sweep's settings with defaults filled in; a ValueError names a bad one."""
    if not isinstance(spec, dict):
        raise ValueError(f'sweep settings must be a mapping, got {spec!r}')
    unknown = sorted(set(spec) - set(KEYS))
    if unknown:
        raise ValueError(f'unknown sweep key(s) {unknown}; known: {list(KEYS)}')
    out = {**copy.deepcopy(DEFAULTS), **spec}
    for name in ('shares', 'levels'):
        values = out[name]
        if not isinstance(values, (list, tuple)) or not values:
            raise ValueError(f'sweep {name} must be a non-empty list, got {values!r}')
        for v in values:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v <= 1:
                raise ValueError(f'sweep {name}: {v!r} is not a fraction in [0, 1]')
    if not all(level > 0 for level in out['levels']):
        raise ValueError(f"sweep levels must be above 0, got {out['levels']!r}")
    for g in out['groupings']:
        if g not in GROUPINGS:
            raise ValueError(f'sweep grouping {g!r} is unknown; known: {sorted(GROUPINGS)}')
    if not isinstance(out['control'], bool):
        raise ValueError(f"sweep control must be true or false, got {out['control']!r}")
    trials = out['trials']
    if isinstance(trials, bool) or not isinstance(trials, int) or trials < 2:
        raise ValueError(f'sweep trials must be an integer >= 2, got {trials!r}')
    return out


def points(spec: dict) -> list[Point]:
    """Every (share, level, grouping) of the settings, then the control."""
    spec = check(spec)
    out = [Point(float(s), float(v), g) for v in spec['levels'] for g in spec['groupings']
           for s in spec['shares']]
    return out + ([Point(None, None, None)] if spec['control'] else [])


def point_config(base: ReplicateConfig, point: Point) -> ReplicateConfig:
    """The replication's settings with this point's reality; the control's reality is not
    the emulator, and its settings say so (and so hash apart)."""
    data = copy.deepcopy(base.data)
    if point.ports:
        data['reality']['ports'] = list(point.ports)
    elif point.shared is None:
        data['reality']['control'] = 'the simulator with the first level\'s combination model'
    else:
        data['reality']['effects'] = point.effects(base.effects).to_dict()
    return build(data)


def control_reality(config: ReplicateConfig):
    """Reality = the core simulator under the first level's combination model."""
    noise = config.levels[0].conditions[0].noise
    from .protocol import play

    def evaluate(genomes, seeds, traced=False):
        episodes = task.Episodes(config.world, noise, config.task)
        fitness, trace = play(episodes, genomes, np.asarray(seeds, np.int64) ^ CONTROL_SALT)
        return trace if traced else fitness
    return evaluate


# --- analysis ----------------------------------------------------------------------------

def difference_ci(a, b, confidence: float = 0.95) -> tuple[float, float, float]:
    """mean(a) - mean(b) and its Welch confidence interval."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    va, vb = a.var(ddof=1) / a.size, b.var(ddof=1) / b.size
    diff = float(a.mean() - b.mean())
    se = math.sqrt(va + vb)
    if se == 0:
        return diff, diff, diff
    df = (va + vb) ** 2 / (va ** 2 / (a.size - 1) + vb ** 2 / (b.size - 1))
    half = float(stats.t.ppf(0.5 + confidence / 2, df)) * se
    return diff, diff - half, diff + half


def scores(store, config: ReplicateConfig, step: int) -> dict[str, list[float]]:
    """Each condition's trial scores at ``step`` (test mean, or best fitness for 1 and 4)."""
    out = {}
    for c in config.conditions:
        values = []
        for t in range(config.trials):
            unit = store.load(c.key, t, step)
            if unit is not None:
                values.append(unit['mean'] if unit['kind'] == 'test' else unit['best_fitness'])
        out[c.name] = values
    return out


def analyse(results: list[tuple[Point, object, ReplicateConfig]]) -> dict:
    """Per point: every step's means per condition, per level the step-3 and step-5
    differences (combination - independent) with their 95% CI, and over all conditions the
    drop and what real training recovers (``recovery``)."""
    rows = []
    for point, store, config in results:
        steps = {s: scores(store, config, s)
                 for s in range(1, 8 if config.ceiling is not None else 6)}
        row = {'point': point.key, 'label': point.label, 'shared': point.shared,
               'level': point.level, 'grouping': point.grouping,
               'means': {s: {c: float(np.mean(v)) for c, v in steps[s].items() if v}
                         for s in steps}, 'differences': {}}
        for level in config.levels:
            combo, indep = (c.name for c in level.conditions)
            for s in (3, 5):
                a, b = steps[s][combo], steps[s][indep]
                if len(a) >= 2 and len(b) >= 2:
                    d, lo, hi = difference_ci(a, b)
                    row['differences'][f'{level.label} step {s}'] = {
                        'difference': d, 'ci_low': lo, 'ci_high': hi, 'n': [len(a), len(b)]}
        row['recovery'] = recovery(steps)
        row['diagnosed'] = _diagnosed(config, steps)
        rows.append(row)
    return {'points': rows}


def _diagnosed(config: ReplicateConfig, steps: dict) -> dict:
    """Diagnosed minus each paper condition at steps 3 and 5, with Welch's 95% CI."""
    out: dict = {}
    d = config.diagnosed
    for s in (3, 5) if d is not None else ():
        for c in config.conditions:
            a, b = steps[s][d.name], steps[s][c.name]
            if c is not d and len(a) >= 2 and len(b) >= 2:
                diff, lo, hi = difference_ci(a, b)
                out[f'{c.name} step {s}'] = {'difference': diff, 'ci_low': lo, 'ci_high': hi}
    return out


def diagnosed_table(analysis: dict, step: int = 3) -> str:
    """Markdown: per point, diagnosed minus each paper condition at ``step``."""
    rows = [r for r in analysis['points'] if r.get('diagnosed')]
    if not rows:
        return ''
    against = [k[:-len(f' step {step}')] for k in rows[0]['diagnosed']
               if k.endswith(f' step {step}')]
    lines = ['| reality | ' + ' | '.join(f'diagnosed - {c}' for c in against) + ' |',
             '|' + ' --- |' * (len(against) + 1)]
    for r in rows:
        cells = [r['diagnosed'].get(f'{c} step {step}') for c in against]
        lines.append(f"| {r['label']} | " + ' | '.join(
            '' if d is None else f"{d['difference']:+.3f} [{d['ci_low']:+.3f}, "
                                 f"{d['ci_high']:+.3f}]" for d in cells) + ' |')
    return '\n'.join(lines) + '\n'


def recovery(steps: dict[int, dict[str, list[float]]]) -> dict:
    """Over all conditions, paired by trial: the drop (step 2 - step 3), what phase 2
    recovers (5 - 3) and, with the ceiling arm, what it recovers (7 - 3); mean and 95% CI."""
    pairs = {'drop': (2, 3), 'recovered': (5, 3), 'ceiling': (7, 3)}
    out = {}
    for name, (a, b) in pairs.items():
        if a not in steps:
            continue
        x = [np.asarray(steps[a][c]) - np.asarray(steps[b][c]) for c in steps[a]
             if steps[a][c] and len(steps[a][c]) == len(steps[b][c])]
        if x and sum(len(v) for v in x) >= 2:
            x = np.concatenate(x)
            half = float(stats.t.ppf(0.975, x.size - 1)) * x.std(ddof=1) / math.sqrt(x.size)
            out[name] = {'mean': float(x.mean()), 'ci_low': float(x.mean() - half),
                         'ci_high': float(x.mean() + half), 'n': int(x.size)}
    return out


def recovery_table(analysis: dict) -> str:
    """Markdown: per point, the drop at the first real test and what real training recovers
    of it, with the paper's phase 2 and (when it ran) the ceiling arm."""
    rows = analysis['points']
    ceiling = any('ceiling' in r['recovery'] for r in rows)
    head = ['reality', 'step 3', 'drop (2 - 3) [95% CI]', 'recovered (5 - 3) [95% CI]']
    head += ['ceiling: recovered (7 - 3) [95% CI]'] if ceiling else []
    lines = ['| ' + ' | '.join(head) + ' |', '|' + ' --- |' * len(head)]
    for r in rows:
        step3 = np.mean(list(r['means'][3].values())) if r['means'][3] else float('nan')
        cells = [r['label'], f'{step3:.3f}']
        for name in ('drop', 'recovered') + (('ceiling',) if ceiling else ()):
            d = r['recovery'].get(name)
            cells.append('' if d is None else '{:+.3f} [{:+.3f}, {:+.3f}]'.format(
                d['mean'], d['ci_low'], d['ci_high']))
        lines.append('| ' + ' | '.join(cells) + ' |')
    return '\n'.join(lines) + '\n'


def table(analysis: dict, step: int = 5) -> str:
    """Markdown: the step's difference (combination - independent) with CI per point."""
    rows = analysis['points']
    levels = _levels(rows)
    columns = [f'{lv}: comb - ind, step {step} [95% CI]' for lv in levels]
    head = '| reality | ' + ' | '.join(columns) + ' |'
    lines = [head, '|' + ' --- |' * (len(levels) + 1)]
    for r in rows:
        cells = []
        for lv in levels:
            d = r['differences'].get(f'{lv} step {step}')
            cells.append('' if d is None else '{:+.3f} [{:+.3f}, {:+.3f}]'.format(
                d['difference'], d['ci_low'], d['ci_high']))
        lines.append(f"| {r['label']} | " + ' | '.join(cells) + ' |')
    return '\n'.join(lines) + '\n'


def _levels(rows) -> list[str]:
    """The levels' labels in the order the settings give them."""
    return list(dict.fromkeys(k.split(' step')[0] for r in rows for k in r['differences']))


def cross_table(analysis: dict, step: int = 3) -> str:
    """Markdown: training noise model (rows) x test world (columns), mean step-3 score
    (phase 1's best, trained in simulation, tested in each reality)."""
    rows = analysis['points']
    conditions = list(rows[0]['means'][step]) if rows else []
    lines = ['| trained under \\ tested in | ' + ' | '.join(r['label'] for r in rows) + ' |',
             '|' + ' --- |' * (len(rows) + 1)]
    for c in conditions:
        cells = [f"{r['means'][step].get(c, float('nan')):.3f}" for r in rows]
        lines.append(f'| {c} | ' + ' | '.join(cells) + ' |')
    sim = ' | '.join(f"{rows[0]['means'][2].get(c, float('nan')):.3f}" for c in conditions)
    lines.append('')
    lines.append(f'Step 2 (the same controllers in simulation), per condition: {sim}.')
    return '\n'.join(lines) + '\n'


def figure(analysis: dict, path, step: int = 5):
    """The step's difference with its CI against each sweep point, one series per level."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    rows = analysis['points']
    levels = _levels(rows)
    fig, ax = plt.subplots(figsize=(max(6.0, 1.1 * len(rows) + 2), 4.2))
    x = np.arange(len(rows))
    for i, lv in enumerate(levels):
        ds = [r['differences'].get(f'{lv} step {step}') for r in rows]
        y = np.array([np.nan if d is None else d['difference'] for d in ds])
        lo = np.array([np.nan if d is None else d['difference'] - d['ci_low'] for d in ds])
        hi = np.array([np.nan if d is None else d['ci_high'] - d['difference'] for d in ds])
        ax.errorbar(x + (i - (len(levels) - 1) / 2) * 0.15, y, yerr=[lo, hi], fmt='o',
                    capsize=3, label=f'{lv} noise in simulation')
    ax.axhline(0.0, color='grey', lw=0.8)
    ax.axhline(0.032, color='red', lw=0.8, ls='--', label="paper's 5% difference (0.032)")
    ax.set_xticks(x)
    ax.set_xticklabels([r['label'].replace(' of ', '\nof ').replace(': ', ':\n')
                        for r in rows], fontsize=7)
    ax.set_ylabel(f'step {step}: combination - independent')
    ax.set_title('Where does modelling sensor dependence pay? (95% CI)')
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
