"""The diagnosed condition: the simulator of a fitted_params.yaml as a condition of
``replicate`` and ``sweep``, beside the paper's two noise models, so the paper's question
extends to "does a diagnosed model transfer better?".

The condition takes the file's noise model and effects; the world and the task are the
replication's, so the conditions differ only in what the simulator adds to the light.
It runs in this process (``EffectEpisodes``) or, through the graph, on a simulator node of
its own; the paper's conditions keep their one batch.  The report compares it with every
paper condition at steps 2, 3 and 5 by Welch's interval (``transfer_stats.versus``).
"""
from __future__ import annotations

import numpy as np

from ..effects.simulate import EffectEpisodes
from .config import Condition
from .fitted import NAME
from .protocol import Evaluator, Simulate, core_simulate, play

STEPS = (2, 3, 5)


def episodes(c: Condition, world, task) -> EffectEpisodes:
    return EffectEpisodes(world, c.noise, task, c.effects)


def in_process(c: Condition, world, task) -> Evaluator:
    """(genomes, seeds) -> fitness in the condition's simulator, in this process."""
    env = episodes(c, world, task)
    return lambda genomes, seeds: play(env, genomes, seeds)[0]


def combine(plain: Simulate, own: dict[str, Evaluator]) -> Simulate:
    """Conditions in ``own`` on their own evaluators, the rest through ``plain``."""
    def simulate(requests):
        out = plain({k: v for k, v in requests.items() if k not in own}) \
            if any(k not in own for k in requests) else {}
        out.update({k: np.asarray(own[k](*v), np.float64) for k, v in requests.items()
                    if k in own})
        return out
    return simulate


def core(config) -> Simulate:
    """Every condition of ``config`` in this process: the paper's in one batch."""
    noise = {c.key: c.noise for c in config.conditions if not c.effects}
    own = {c.key: in_process(c, config.world, config.task)
           for c in config.conditions if c.effects}
    return combine(core_simulate(noise, config.world, config.task), own)


def analyse(results) -> dict | None:
    """Diagnosed against every paper condition at steps 2, 3 and 5 (Welch's interval)."""
    from .transfer_stats import versus
    config = results.config
    if config.diagnosed is None:
        return None
    d = config.diagnosed
    rows = []
    for step in STEPS:
        mine = results.scores(d, step)
        for c in config.conditions:
            if c is not d:
                v = versus(mine, results.scores(c, step), (NAME, c.name))
                rows.append({'step': step, 'against': c.name, **v})
    return {'effects': [e.name for e in d.effects], 'rows': rows}


def markdown(analysis: dict | None) -> str:
    if not analysis:
        return ''
    lines = ['## Does the diagnosed simulator transfer better?', '',
             f"The condition `diagnosed` evolves in the simulator of the params file "
             f"(effects: {', '.join(analysis['effects']) or 'none'}). Step 2 is its "
             'simulation test, steps 3 and 5 the real tests; each row is diagnosed minus '
             "the paper's condition, with Welch's 95% interval.", '',
             '| step | against | diagnosed - it [95% CI] | verdict |',
             '| --- | --- | --- | --- |']
    for r in analysis['rows']:
        lines.append(f"| {r['step']} | {r['against']} | {r['difference']:+.3f} "
                     f"[{r['ci_low']:+.3f}, {r['ci_high']:+.3f}] | {r['verdict']} |")
    return '\n'.join(lines) + '\n'


def summary(analysis: dict | None) -> str:
    """One line for the terminal: the first real test against each paper condition."""
    if not analysis:
        return ''
    parts = [f"{r['against']} {r['difference']:+.3f} ({r['verdict']})"
             for r in analysis['rows'] if r['step'] == 3]
    return 'Diagnosed at the first real test (step 3), against: ' + '; '.join(parts) + '.\n'
