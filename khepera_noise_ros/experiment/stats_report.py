"""The report's statistics: per-step comparisons beside the paper, and the power analysis.

``judged`` adds the estimates, tests and verdict of one comparison to the
analysis; the ``*_md`` functions render them; ``power_before_run`` is what
``replicate`` prints before it starts.  Pure: numbers in, text out.
"""
from __future__ import annotations

import math
from dataclasses import asdict

from . import power as pw
from .stats import compare, p_text
from .verdict import judge

# What section 4.4 says of each step's comparison (the paper gives numbers only for step 5,
# in Table 1, and for the generation of the best).
PAPER_STEPS = {
    '5%': {1: 'almost identical', 2: 'almost identical',
           3: 'both drop dramatically; independent more, n.s.',
           4: 'both improve, not to step 1', 5: '0.795 vs 0.763, p < 0.05'},
    '10%': {1: 'similar', 2: 'similar', 3: 'similar', 4: 'similar',
            5: '0.770 vs 0.757, similar'},
}
GENERATION_WORDS = ('later', 'sooner')


def settings(config) -> dict:
    """alpha, target power and the equivalence margin: the config's ``statistics`` mapping
    where it has one, else two-sided 5%, 80% and the paper's 0.032."""
    given = config.data.get('statistics') or {}
    return {'alpha': given.get('alpha', pw.ALPHA), 'target': given.get('power', pw.TARGET_POWER),
            'margin': given.get('margin', pw.PAPER_DIFFERENCE)}


def step_reference(level: str, step: int, table1: dict) -> float | None:
    """The paper's difference (combination - independent) at a step, where it gives one."""
    c, i = table1.get(f'{level} combination'), table1.get(f'{level} independent')
    return c - i if step == 5 and c is not None and i is not None else None


def judged(a, b, margin: float, alpha: float, reference: float | None = None,
           words: tuple[str, str] = ('better', 'worse'), digits: int = 3) -> dict:
    """The comparison of a (combination) against b (independent) and its verdict.

    Args:
        a, b: the two samples (>= 2 values each).
        margin: equivalence margin; alpha: level of the tests.
        reference: the paper's difference a - b, if it gives one.
        words, digits: how the verdict reads (see ``verdict.judge``).

    Returns:
        {'comparison': asdict(Comparison), 'verdict': asdict(Verdict), 'reference': ...}
    """
    c = compare(a, b, margin=margin, alpha=alpha)
    v = judge(c, reference=reference, words=words, digits=digits)
    return {'comparison': asdict(c), 'verdict': asdict(v), 'reference': reference}


def _f(x, digits: int = 3) -> str:
    return 'n/a' if x is None or not math.isfinite(x) else f'{x:.{digits}f}'


def _interval(x: float, low: float, high: float, digits: int = 3) -> str:
    """'+0.041 [0.032, 0.050]'; without the interval where it is undefined."""
    if not math.isfinite(x):
        return 'n/a'
    if not math.isfinite(low):
        return f'{x:+.{digits}f}'
    return f'{x:+.{digits}f} [{low:.{digits}f}, {high:.{digits}f}]'


def _p(p: float) -> str:
    """'0.033', '< 0.001' or 'n/a'."""
    return p_text(p).removeprefix('p = ').removeprefix('p ')


HEAD = ('Step', 'What', 'Paper', 'Combination', 'Independent', 'Difference [95% CI]',
        "Hedges' g [95% CI]", 'Welch p', 'Rank p (P(c > i))', 'TOST p (± margin)', 'Verdict')


def _row(first: tuple[str, str, str], test: dict, digits: int = 3) -> str:
    c, v = test['comparison'], test['verdict']
    a, b, ci, g = c['a'], c['b'], c['interval'], c['effect']
    eq, rank = c['equivalence'], c['rank']
    cells = (*first, f"{_f(a['mean'], digits)} ± {_f(a['sd'], digits)}",
             f"{_f(b['mean'], digits)} ± {_f(b['sd'], digits)}",
             _interval(ci['difference'], ci['ci_low'], ci['ci_high'], digits),
             _interval(g['g'], g['ci_low'], g['ci_high'], 2),
             _p(c['welch']['p']), f"{_p(rank['p'])} ({rank['superiority']:.2f})",
             f"{_p(eq['p'])} (± {eq['margin']:g})", f"**{v['kind']}**")
    return '| ' + ' | '.join(cells) + ' |'


def level_table(level: str, tests: list[dict], steps: dict) -> str:
    """Markdown: one row per step of ``level`` (tests from the analysis), then the verdicts.

    Args:
        level: the level's label, e.g. '5%'.
        tests: the analysis's step tests of that level (each with 'step' and ``judged``'s keys).
        steps: step number -> what the step is.

    Returns:
        The table, and below it each step's verdict sentence.
    """
    paper = PAPER_STEPS.get(level, {})
    rows = [_row((str(t['step']), steps[t['step']], paper.get(t['step'], '-')), t)
            for t in tests]
    notes = [f"- Step {t['step']}: {t['verdict']['text']}." for t in tests]
    return '\n'.join([f"| {' | '.join(HEAD)} |", '|' + ' --- |' * len(HEAD), *rows, '',
                      *notes, ''])


def kinds_text(tests: list[dict]) -> str:
    """'equivalent at steps 1, 2; underpowered at step 5': the verdicts of several steps."""
    steps: dict[str, list[str]] = {}
    for t in tests:
        steps.setdefault(t['verdict']['kind'], []).append(str(t['step']))
    return '; '.join(f"{kind} at step{'s' if len(s) > 1 else ''} {', '.join(s)}"
                     for kind, s in steps.items())


def generation_md(tests: list[dict]) -> str:
    """Markdown: the generation of phase 1's best, per level, beside the paper's."""
    rows, notes = [], []
    for t in tests:
        paper = t.get('paper')
        paper_text = (f"{paper['combination']} vs {paper['independent']}, p < 0.05"
                      if paper else '-')
        rows.append(_row((t['level'], 'generation of the best', paper_text), t, 1))
        notes.append(f"- {t['level']}: {t['verdict']['text']}.")
    head = ('Level',) + HEAD[1:]
    return '\n'.join(['## Generation at which phase 1 found its best\n',
                      f"| {' | '.join(head)} |", '|' + ' --- |' * len(head), *rows, '',
                      *notes, ''])


def statistics_intro(margin: float, alpha: float) -> str:
    return (f'Combination against independent at each step: the difference (combination − '
            f'independent) with its 95% Welch interval, Hedges\' g with its exact interval, '
            f"Welch's t-test and the Mann-Whitney rank test (two-sided, α = {alpha:g}; in "
            f'brackets the probability that a combination trial beats an independent one), '
            f'and the equivalence test (TOST) against a margin of ±{margin:g} stated before '
            f'the run. The verdict comes from the interval and the TOST, not from p alone: '
            f'*difference*, *equivalent* (no difference larger than the margin), '
            f'*underpowered* (the interval admits both the difference of interest and none), '
            f'*inconclusive*, or *trivial difference* (significant but within the margin); '
            f'the rules are in docs/statistics.md.\n')


def _measured_plans(tests: list[dict], difference: float, n: int, alpha, target) -> list:
    plans = []
    for t in tests:
        c = t['comparison']
        sds = (c['a']['sd'], c['b']['sd'])
        if all(math.isfinite(s) for s in sds) and pw.pooled_sd(*sds) > 0:
            plans.append(pw.plan(pw.pooled_sd(*sds), n, difference, alpha, target,
                                 f"measured: {t['level']} step {t['step']}"))
    return plans


def _design_lines(n: int, difference: float, alpha: float, target: float) -> list[str]:
    return [f'With {n} trials per model, a two-sided Welch test at α = {alpha:g} finds a true '
            f'{difference:g} with {target:.0%} power only if the SD per trial is at most '
            f'{pw.largest_sd(difference, n, alpha, target):.3f}. The paper found its 0.032 '
            f'significant with 10 trials per model, so its SD was at most '
            f'{pw.significant_below(pw.PAPER_DIFFERENCE, 10, alpha):.3f}.']


def power_md(trials: int, tests: list[dict], margin: float, alpha: float,
             target: float) -> str:
    """Markdown: the power of this run's design at the spreads it measured, and assumed ones.

    Args:
        trials: trials per model; tests: the analysis's step tests (``judged``'s keys).
        margin: the difference of interest (the paper's 0.032 unless configured).
        alpha, target: the tests' level and the power asked for.

    Returns:
        The section, with one row per compared step (pooled SD of the two models).
    """
    plans = _measured_plans([t for t in tests if t['step'] in (2, 3, 5)], margin, trials,
                            alpha, target)
    plans += [pw.plan(sd, trials, margin, alpha, target) for sd in pw.ASSUMED_SDS]
    return '\n'.join(['## Power: what this design can detect\n',
                      f"Two-sided Welch t-test at α = {alpha:g}, {trials} trials per model; "
                      f'"detectable" is the difference found with {target:.0%} power; the '
                      f'difference of interest is {margin:g}. A measured SD is the pooled SD '
                      f'of the two models at that step.\n',
                      pw.plan_table(plans, f'{margin:g}'), '',
                      *_design_lines(trials, margin, alpha, target), ''])


def power_before_run(config, store=None) -> str:
    """The power analysis ``replicate`` prints before it runs anything.

    Args:
        config: the ``ReplicateConfig`` (its ``trials`` and its ``statistics``, if any).
        store: the results ``Store``; where it already holds finished step-5 tests of
            both models of a level (a resumed run), their spread is used too.

    Returns:
        A few lines of text: the table for the assumed (and any measured) SDs.
    """
    s = settings(config)
    plans = []
    if store is not None:
        for level in config.levels:
            scores = [[u['mean'] for u in (store.load(c.key, t, 5) for t in range(config.trials))
                       if u is not None] for c in level.conditions]
            if all(len(x) >= 2 for x in scores):
                sds = [_sd(x) for x in scores]
                if pw.pooled_sd(*sds) > 0:
                    plans.append(pw.plan(pw.pooled_sd(*sds), config.trials, s['margin'],
                                         s['alpha'], s['target'],
                                         f'measured: {level.label} step 5, '
                                         f'{min(map(len, scores))} trials'))
    plans += [pw.plan(sd, config.trials, s['margin'], s['alpha'], s['target'])
              for sd in pw.ASSUMED_SDS]
    lines = [f"Power analysis (before the run): step 5, {config.trials} trials per model, "
             f"two-sided Welch t-test at alpha {s['alpha']:g}.",
             pw.plan_table(plans, f"{s['margin']:g}"),
             *_design_lines(config.trials, s['margin'], s['alpha'], s['target'])]
    return '\n'.join(lines) + '\n'


def _sd(x: list[float]) -> float:
    mean = sum(x) / len(x)
    return math.sqrt(sum((v - mean) ** 2 for v in x) / (len(x) - 1))
