"""The report: our results beside the paper's, as Markdown with figures, JSON and CSV.

Everything here is computed from the results store alone, so a report can be
rebuilt from a finished (or resumed) run without running anything again.
"""
from __future__ import annotations

import csv
import io
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..files import atomic_write_text, write_json
from . import diagnosed, figures, stats_report
from .config import Level, ReplicateConfig
from .protocol import CEILING_STEPS, STEPS
from .recovery import recovery, recovery_md, recovery_summary
from .stats import Summary, describe, rank_test, summarize, ttest
from .store import Store

RESULTS_FORMAT = 'khepera-noise-replicate-results/1'
ALPHA = 0.05
# What Meeden (1998) reports (section 4.4, Figure 8 and Table 1).
PAPER = {
    'table1': {'5% combination': 0.7952, '10% combination': 0.7696,
               '5% independent': 0.7627, '10% independent': 0.7567},
    'best_generation': {'5%': {'combination': 35.0, 'independent': 42.8}},
    'figure8': 0.818,
}
# The score of a step: the best fitness seen in training, the mean over test episodes.
SCORE = {1: 'best_fitness', 2: 'mean', 3: 'mean', 4: 'best_fitness', 5: 'mean',
         6: 'best_fitness', 7: 'mean'}
COLLAPSE = 0.5       # a final real score below this is a controller that stopped working
CSV_COLUMNS = ('condition', 'level', 'model', 'trial', 'step', 'what', 'world', 'score',
               'best_generation', 'evaluations')


@dataclass
class Results:
    """Every finished unit of a complete run, by (condition key, trial, step)."""

    config: ReplicateConfig
    units: dict

    @property
    def steps(self) -> dict[int, str]:
        """The steps run: 1-5, and 6-7 with the ceiling arm."""
        return {**STEPS, **(CEILING_STEPS if self.config.ceiling is not None else {})}

    def scores(self, condition, step: int) -> np.ndarray:
        return np.array([self.units[condition.key, t, step][SCORE[step]]
                         for t in range(self.config.trials)])

    def best_generations(self, condition) -> np.ndarray:
        return np.array([self.units[condition.key, t, 1]['best_generation']
                         for t in range(self.config.trials)], dtype=float)


def collect(config: ReplicateConfig, store: Store) -> Results:
    """Load the whole run; a missing unit is an error that names it."""
    units = {}
    steps = {**STEPS, **(CEILING_STEPS if config.ceiling is not None else {})}
    for c in config.conditions:
        for t in range(config.trials):
            for step in steps:
                unit = store.load(c.key, t, step)
                if unit is None:
                    raise RuntimeError(f'{c.name} trial {t + 1} step {step} is not finished; '
                                       f'run the experiment to the end first')
                units[c.key, t, step] = unit
    return Results(config, units)


def analyse(results: Results, figure8: dict | None) -> dict:
    config = results.config
    steps = {c.name: [asdict(summarize(results.scores(c, s))) for s in STEPS]
             for c in config.conditions}
    stats_settings = stats_report.settings(config)
    analysis = {'table1': _table1(results), 'steps': steps, 'statistics': stats_settings,
                'tests': [_step_test(results, level, s, stats_settings)
                          for level in config.levels for s in STEPS],
                'best_generation': [_generation_test(results, level, stats_settings['alpha'])
                                    for level in config.levels],
                'figure8': figure8, 'recovery': recovery(results),
                'diagnosed': diagnosed.analyse(results)}
    analysis['findings'] = findings(analysis, config)
    return analysis


def _table1(results: Results) -> list[dict]:
    rows = []
    for c in results.config.conditions:
        x = results.scores(c, 5)
        s = summarize(x)
        rows.append({'condition': c.name, 'mean': s.mean, 'sd': s.sd, 'ci': [s.ci_low, s.ci_high],
                     'n': s.n, 'median': float(np.median(x)),
                     'collapsed': int((x < COLLAPSE).sum()),
                     'paper': PAPER['table1'].get(c.name)})
    rows.sort(key=lambda r: -r['mean'])
    paper_rank = {name: k + 1 for k, name in
                  enumerate(sorted(PAPER['table1'], key=lambda n: -PAPER['table1'][n]))}
    for k, row in enumerate(rows):
        row['rank'], row['paper_rank'] = k + 1, paper_rank.get(row['condition'])
    return rows


def _compare(level: Level, a, b, **judging) -> dict:
    test = ttest(a, b)
    return {'level': level.label, **asdict(test), 'text': describe(test),
            'rank_p': rank_test(a, b), **stats_report.judged(a, b, **judging)}


def _step_test(results: Results, level: Level, step: int, stats_settings: dict) -> dict:
    combo, indep = level.conditions
    reference = stats_report.step_reference(level.label, step, PAPER['table1'])
    return {'step': step, 'what': STEPS[step],
            **_compare(level, results.scores(combo, step), results.scores(indep, step),
                       margin=stats_settings['margin'], alpha=stats_settings['alpha'],
                       reference=reference)}


def _generation_test(results: Results, level: Level, alpha: float) -> dict:
    combo, indep = level.conditions
    paper = PAPER['best_generation'].get(level.label)
    gap = PAPER['best_generation']['5%']
    out = _compare(level, results.best_generations(combo), results.best_generations(indep),
                   margin=abs(gap['combination'] - gap['independent']), alpha=alpha,
                   reference=paper and paper['combination'] - paper['independent'],
                   words=stats_report.GENERATION_WORDS, digits=1)
    out['paper'] = paper
    return out


# --- agreement with the paper ------------------------------------------------------------

def findings(analysis: dict, config: ReplicateConfig) -> list[dict]:
    """Each claim of the paper that our settings can test, with our number and a verdict."""
    labels = {level.label for level in config.levels}
    out = [_ranking(analysis)]
    if '5%' in labels:
        out += _five_percent(analysis)
    if '10%' in labels:
        out.append(_ten_percent(analysis))
    if analysis['figure8'] is not None:
        ours = analysis['figure8']['mean']
        out.append(_finding('Figure 8: a successful controller averages 0.818 in a test',
                            '0.818', f'{ours:.3f}', abs(ours - PAPER['figure8']) < 0.05))
    return out


def _finding(claim: str, paper: str, ours: str, agrees: bool, direction: bool = False,
             underpowered: bool = False) -> dict:
    """``direction``: a significant difference claimed, and ours has its sign but not p;
    ``underpowered``: our interval admits both the claimed difference and none."""
    verdict = 'agrees' if agrees else 'underpowered' if underpowered else \
        'same direction, not significant' if direction else 'differs'
    return {'claim': claim, 'paper': paper, 'ours': ours, 'verdict': verdict}


def _test(analysis: dict, level: str, step: int) -> dict:
    return next(t for t in analysis['tests'] if t['level'] == level and t['step'] == step)


def _mean(analysis: dict, name: str, step: int) -> float:
    return analysis['steps'][name][step - 1]['mean']


def _ranking(analysis: dict) -> dict:
    ours = [r['condition'] for r in analysis['table1'] if r['paper'] is not None]
    paper = sorted(PAPER['table1'], key=lambda n: -PAPER['table1'][n])
    return _finding('Table 1 ranking of final real-world performance', ' > '.join(paper),
                    ' > '.join(ours), ours == paper)


def _five_percent(analysis: dict) -> list[dict]:
    c, i = '5% combination', '5% independent'
    out = []
    similar = [_test(analysis, '5%', s) for s in (1, 2)]
    out.append(_finding(
        '5%: steps 1 and 2 (simulation) almost identical for both models',
        'no difference reported', '; '.join(f"step {t['step']}: {t['mean_a']:.3f} vs "
                                            f"{t['mean_b']:.3f}, {t['text']}" for t in similar)
        + f'; {stats_report.kinds_text(similar)}', all(t['p'] >= ALPHA for t in similar)))
    drops = {m: _mean(analysis, m, 2) - _mean(analysis, m, 3) for m in (c, i)}
    out.append(_finding(
        '5%: real test (step 3) drops dramatically from the simulation test (step 2)',
        'large drop for both', f'drop {drops[c]:.3f} (combination), {drops[i]:.3f} '
                               f'(independent)', min(drops.values()) > 0.02))
    step3 = _test(analysis, '5%', 3)
    out.append(_finding(
        '5%: the independent model drops more at step 3, not significantly',
        'larger drop for independent, n.s.',
        f"{drops[i]:.3f} vs {drops[c]:.3f}; step 3 {step3['text']}",
        drops[i] > drops[c] and step3['p'] >= ALPHA))
    up = {m: (_mean(analysis, m, 3), _mean(analysis, m, 4), _mean(analysis, m, 1)) for m in (c, i)}
    out.append(_finding(
        '5%: real training (step 4) improves on step 3, but not to the level of step 1',
        'step 3 < step 4 < step 1, both models',
        '; '.join(f'{m.split()[1]}: {a:.3f} < {b:.3f} < {d:.3f}' for m, (a, b, d) in up.items()),
        all(a < b < d for a, b, d in up.values())))
    gain = {m: _mean(analysis, m, 5) - _mean(analysis, m, 3) for m in (c, i)}
    out.append(_finding(
        '5%: after real training the real test is better than before it (step 5 > step 3)',
        'step 3 far below, step 5 near the simulation level (Figure 9)',
        f'step 5 - step 3: {gain[c]:+.3f} (combination), {gain[i]:+.3f} (independent)',
        min(gain.values()) > 0))
    step5 = _test(analysis, '5%', 5)
    out.append(_finding(
        '5%: final real test (step 5): combination significantly better',
        '0.795 vs 0.763, p < 0.05', f"{step5['mean_a']:.3f} vs {step5['mean_b']:.3f}: "
                                    f"{step5['verdict']['text']}",
        step5['t'] > 0 and step5['p'] < ALPHA, step5['t'] > 0,
        step5['verdict']['kind'] == 'underpowered'))
    gen = next(g for g in analysis['best_generation'] if g['level'] == '5%')
    out.append(_finding(
        '5%: phase 1 reaches its best fitness sooner with the combination model',
        'generation 35.0 vs 42.8, p < 0.05',
        f"generation {gen['mean_a']:.1f} vs {gen['mean_b']:.1f}: {gen['verdict']['text']}",
        gen['t'] < 0 and gen['p'] < ALPHA, gen['t'] < 0, gen['verdict']['kind'] == 'underpowered'))
    return out


def _ten_percent(analysis: dict) -> dict:
    tests = [_test(analysis, '10%', s) for s in STEPS]
    low = min(tests, key=lambda t: t['p'])
    return _finding('10%: both models perform similarly at every step',
                    'no marked difference',
                    f"smallest p = {low['p']:.3f} (step {low['step']}; rank test "
                    f"p = {low['rank_p']:.3f}); {stats_report.kinds_text(tests)}",
                    all(t['p'] >= ALPHA for t in tests))


# --- writing -----------------------------------------------------------------------------

def write(out, config: ReplicateConfig, store: Store, backends: dict, sessions: list) -> dict:
    """Analyse the stored run and write report.md, figures, results.json and results.csv."""
    out = Path(out)
    results = collect(config, store)
    analysis = analyse(results, figure8(results))
    draw(out, results, analysis)
    document = {'format': RESULTS_FORMAT, 'config_hash': config.hash, 'settings': config.data,
                'backends': backends, 'sessions': sessions, 'analysis': analysis,
                'units': [results.units[k] for k in sorted(results.units)]}
    write_json(out / 'results.json', document)
    atomic_write_text(out / 'results.csv', _csv(results))
    atomic_write_text(out / 'report.md', markdown(config, analysis, backends, sessions))
    return analysis


def figure8(results: Results) -> dict | None:
    """The best controller's final real test, step by step (None if it was not traced)."""
    config = results.config
    condition, trial = max(((c, t) for c in config.conditions for t in range(config.trials)),
                           key=lambda u: results.units[u[0].key, u[1], 5]['mean'])
    unit = results.units[condition.key, trial, 5]
    if 'step_fitness' not in unit:
        return None
    return {'condition': condition.name, 'trial': trial + 1, 'world': unit['world'],
            'seed': unit['seeds'][0], 'fitness': unit['step_fitness'][0],
            'mean': unit['fitness'][0]}


def draw(out: Path, results: Results, analysis: dict) -> None:
    config = results.config
    for level in config.levels:
        rows = {c.model: [Summary(**s) for s in analysis['steps'][c.name]]
                for c in level.conditions}
        paper = {c.model: PAPER['table1'][c.name] for c in level.conditions
                 if c.name in PAPER['table1']}
        figures.steps(out / f'{level.figure}.png', level.label, rows, paper,
                      _figure_name(level.figure))
    if analysis['figure8'] is not None:
        f8 = analysis['figure8']
        figures.trace(out / 'fig8.png', f8['fitness'], config.task.perturb_every,
                      PAPER['figure8'], f"Figure 8: best controller ({f8['condition']}, trial "
                                        f"{f8['trial']}) in a {f8['world']} test")
    histories = {c.name: {s: np.array([[h[1:3] for h in results.units[c.key, t, s]['history']]
                                       for t in range(config.trials)]) for s in (1, 4)}
                 for c in config.conditions}
    figures.curves(out / 'curves.png', histories)


def _csv(results: Results) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator='\n')
    writer.writerow(CSV_COLUMNS)
    for c in results.config.conditions:
        for t in range(results.config.trials):
            for step, what in results.steps.items():
                unit = results.units[c.key, t, step]
                writer.writerow([c.name, c.level, c.model, t + 1, step, what,
                                 unit['world'], repr(float(unit[SCORE[step]])),
                                 unit.get('best_generation', ''), unit.get('evaluations', '')])
    return buffer.getvalue()


def _f(x: float, digits: int = 4) -> str:
    return 'n/a' if x is None or not math.isfinite(x) else f'{x:.{digits}f}'


def markdown(config: ReplicateConfig, analysis: dict, backends: dict, sessions: list) -> str:
    s = analysis['statistics']
    parts = [_head(config, analysis, backends, sessions), _table1_md(analysis),
             _steps_md(config, analysis), diagnosed.markdown(analysis.get('diagnosed')),
             recovery_md(config, analysis['recovery']),
             stats_report.generation_md(analysis['best_generation']),
             stats_report.power_md(config.trials, analysis['tests'], s['margin'], s['alpha'],
                                   s['target']),
             _figure8_md(config, analysis), _findings_md(analysis), _why_md(config, analysis),
             _files_md(config)]
    return '\n'.join(parts)


def _head(config: ReplicateConfig, analysis: dict, backends: dict, sessions: list) -> str:
    total = sum(s['elapsed_s'] for s in sessions)
    levels = '; '.join(f"{lv.label}: {lv.conditions[0].noise.dependent:.0%} dependent + "
                       f"{lv.conditions[0].noise.independent:.0%} independent against "
                       f"{lv.conditions[1].noise.independent:.0%} independent"
                       for lv in config.levels)
    return f"""# Replication of Meeden (1998), section 4

Combination (dependent + independent) against independent sensor noise, for evolving a
Khepera light-centring controller in simulation and transferring it to reality.

- **Conditions**: {levels}; dependence groups {config.data['dependence_groups']},
  {config.data['distribution']} noise.
- **Trials**: {config.trials} per condition, each through steps 1-5: evolve in simulation
  ({config.phase1.generations} generations of {config.phase1.population}), test in simulation,
  test in reality, evolve in reality ({config.phase2.generations} generations of
  {config.phase2.population}, seeded from phase 1's best), test in reality. A test is
  {config.test_episodes} episode(s) of {config.task.steps} steps.
- **Simulation**: {backends.get('simulation', '?')}.
- **Reality**: {backends.get('reality', '?')}. Our "reality" is a robot emulator with
  effects of its own, not the author's lab.
- **Settings**: `config.yaml` (hash `{config.hash}`); seed {config.seed}; protocol
  {config.data['protocol']}. Unstated in the paper, calibrated (docs/calibration.md):
  lamp gain {config.world.gain:g}, knock ±{config.task.perturbation_deg:g}°,
  {config.world.deg_per_power:g}° per unit of power.
- **Run time**: {total:.0f} s over {len(sessions)} session(s) on this machine.

Scores: steps 1 and 4 are {_training_score(config)};
steps 2, 3 and 5 are the mean fitness of the test. Tests of
combination against independent are {analysis['tests'][0]['test']}s, two-sided (the paper
says only "t-tests"; Welch's does not assume the two models scatter equally across trials).
"""


def _table1_md(analysis: dict) -> str:
    rows = '\n'.join(
        f"| {r['rank']} | {r['condition']} | {_f(r['mean'])} | {_f(r['sd'])} | "
        f"[{_f(r['ci'][0])}, {_f(r['ci'][1])}] | {_f(r['median'])} | {r['collapsed']} | "
        f"{r['n']} | {r['paper_rank'] or '-'} | {_f(r['paper']) if r['paper'] else '-'} |"
        for r in analysis['table1'])
    head = ('Rank', 'Noise model', 'Mean', 'SD', '95% CI', 'Median', f'Below {COLLAPSE}', 'n',
            "Paper's rank", "Paper's value")
    return (f"## Table 1: final real-world performance (step 5), ranked\n\n"
            f"| {' | '.join(head)} |\n|{' --- |' * len(head)}\n{rows}\n")


def _steps_md(config: ReplicateConfig, analysis: dict) -> str:
    out = ['## Figures 9 and 10: training and testing performance per step\n',
           stats_report.statistics_intro(analysis['statistics']['margin'],
                                         analysis['statistics']['alpha'])]
    for level in config.levels:
        out.append(f'![{level.figure}]({level.figure}.png)\n')
        out.append(f'**{_figure_name(level.figure)}, {level.label} noise** (mean ± SD over '
                   f'trials)\n')
        out.append(stats_report.level_table(
            level.label, [t for t in analysis['tests'] if t['level'] == level.label], STEPS))
    return '\n'.join(out)


def _figure_name(figure: str) -> str:
    """'fig9' -> 'Figure 9'; other names as they are."""
    return f'Figure {figure[3:]}' if figure[:3] == 'fig' and figure[3:].isdigit() else figure


def _figure8_md(config: ReplicateConfig, analysis: dict) -> str:
    f8 = analysis['figure8']
    if f8 is None:
        return '## Figure 8\n\nNo trace was recorded.\n'
    return f"""## Figure 8: fitness at each step of a test of the best controller

![fig8](fig8.png)

The controller with the best final real-world test ({f8['condition']}, trial {f8['trial']}):
its step 5 test episode in {f8['world']}, average fitness {f8['mean']:.3f} (the paper:
{PAPER['figure8']}). Grey lines mark the steps where the heading is perturbed
(every {config.task.perturb_every} steps), where the paper's fitness drops too.
"""


def _findings_md(analysis: dict) -> str:
    rows = '\n'.join(f"| {f['claim']} | {f['paper']} | {f['ours']} | **{f['verdict']}** |"
                     for f in analysis['findings'])
    return f"""## Where we agree with the paper and where we differ

{_tally(analysis)}.

| The paper finds | Paper | Ours | Verdict |
| --- | --- | --- | --- |
{rows}
"""


def _training_score(config: ReplicateConfig) -> str:
    if config.phase1.best == 'ever':
        return ('the best fitness seen during evolution (one episode per evaluation, as in '
                'the paper)')
    return (f'the mean of the chosen best over its re-test ({config.phase1.retest_episodes} '
            "episodes of its own, apart from the test's)")


def _why_md(config: ReplicateConfig, analysis: dict) -> str:
    effects = ', '.join(f'`{e}`' for e in config.effects.enabled) or 'none'
    lines = ['## Why differences can be expected\n',
             "- **Our reality is not the author's.** The paper's reality was one Khepera in one "
             'room. Ours (unless run with `--port`) is an emulator whose departures from the '
             f'simulator are our guesses at such a room: effects {effects}, and '
             f'{config.effects.sensor_noise:.0%} independent sensor noise. Whether the '
             'combination model transfers better depends on how much of the real noise is '
             'shared between sensors, which is exactly what differs. The emulator draws its '
             "noise from each robot's own stream rather than from the episode seed, so a "
             'reality test repeated (or resumed) is a new sample, as on a real robot.',
             '- **Our simulator is a re-creation.** The light response and turning follow '
             "Michel's Khepera Simulator as described, with a lamp geometry the paper does "
             'not give, so absolute fitness values need not match.',
             '- **Steps 1 and 4 are maxima of noisy scores.** The best of about '
             f'{config.phase1.population * (config.phase1.generations + 1)} single-episode '
             'evaluations is a lucky one, so training scores sit above test scores even '
             'without any reality gap; the generation of the best is likewise partly luck.'
             if config.phase1.best == 'ever' else
             '- **Steps 1 and 4 are re-test means.** The best of the last population, '
             'each member re-tested on its own episodes, so they are only slightly '
             'optimistic; the generation of the best is where the population first held '
             'its highest single evaluation.']
    lines += _collapse_lines(config, analysis)
    return '\n'.join(lines) + '\n'


def _collapse_lines(config: ReplicateConfig, analysis: dict) -> list[str]:
    collapsed = sum(r['collapsed'] for r in analysis['table1'])
    if not collapsed:
        return []
    total = sum(r['n'] for r in analysis['table1'])
    return [f'- **Some controllers collapse in the final test.** {collapsed} of {total} '
            f'step-5 scores are below {COLLAPSE}. Phase 2 keeps the best single episode of '
            f'{config.phase2.population * (config.phase2.generations + 1)} evaluations of '
            f'mutants (every gene moved by up to ±{config.phase2.mutation_range:g}), so a '
            'mutant that was lucky once can win and then fail (typically it loses the lamp '
            'after a knock and does not find it again, or stops turning: power 0 scores 0). '
            'The paper reports final averages of 0.76-0.80 and says nothing of such '
            'failures; its single robot may have been '
            'kinder, or its best chosen otherwise. These outliers inflate the SDs: the '
            'medians and the rank test are the fairer comparison.']


def _files_md(config: ReplicateConfig) -> str:
    figs = ', '.join(f'`{lv.figure}.png`' for lv in config.levels)
    return f"""## Files

- `results.json`: settings, analysis and every unit (genomes, seeds, per-episode fitness,
  per-generation history); `results.csv`: one row per condition, trial and step.
- {figs}, `fig8.png`, `curves.png` (best and mean fitness per generation, both phases).
- `config.yaml`: the settings used; `units/`: the resumable store the report is built from.
"""


VERDICT_WORDS = {'agrees': 'agree', 'same direction, not significant':
                 'in the same direction but not significant',
                 'underpowered': 'underpowered (our interval admits the effect and none)',
                 'differs': 'differ'}


def _tally(analysis: dict) -> str:
    """'3 agree, 2 in the same direction but not significant, 5 differ'."""
    verdicts = [f['verdict'] for f in analysis['findings']]
    return ', '.join(f'{verdicts.count(v)} {words}' for v, words in VERDICT_WORDS.items()
                     if v in verdicts)


def summary(analysis: dict) -> str:
    """A few lines for the terminal: Table 1 and the verdicts."""
    lines = ['Table 1 (final real-world performance, step 5):']
    lines += [f"  {r['rank']}. {r['condition']:<17} {r['mean']:.4f} ± {r['sd']:.4f}   "
              f"paper {_f(r['paper']) if r['paper'] else '-'}" for r in analysis['table1']]
    lines.append(recovery_summary(analysis['recovery']))
    lines += [x for x in [diagnosed.summary(analysis.get('diagnosed')).rstrip()] if x]
    lines.append(f"Of the paper's findings: {_tally(analysis)}.")
    return '\n'.join(lines) + '\n'
