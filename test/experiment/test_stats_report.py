"""The report's statistics and power sections, and the power analysis replicate prints."""
import dataclasses
import json

import numpy as np
import pytest
import yaml

from khepera_noise_ros import cli
from khepera_noise_ros.experiment import power as pw
from khepera_noise_ros.experiment import report, stats, stats_report, verdict
from khepera_noise_ros.experiment.protocol import STEPS
from khepera_noise_ros.experiment.store import Store
from khepera_noise_ros.testing.experiments import synthetic, tiny


def test_judged_is_compare_and_judge_in_plain_form():
    rng = np.random.default_rng(2)
    a, b = rng.normal(0.8, 0.02, 10), rng.normal(0.77, 0.02, 10)
    out = stats_report.judged(a, b, margin=0.032, alpha=0.05, reference=0.032)
    c = stats.compare(a, b)
    assert out['comparison'] == dataclasses.asdict(c)
    assert out['verdict'] == dataclasses.asdict(verdict.judge(c, reference=0.032))
    assert out['reference'] == 0.032
    json.dumps(out)                                    # goes into results.json as it is


def test_settings_default_to_the_paper_and_follow_a_statistics_mapping():
    config = tiny()
    assert stats_report.settings(config) == {'alpha': 0.05, 'target': 0.8, 'margin': 0.032}
    changed = dataclasses.replace(config, data={**config.data, 'statistics':
                                                {'margin': 0.02, 'power': 0.9}})
    assert stats_report.settings(changed) == {'alpha': 0.05, 'target': 0.9, 'margin': 0.02}


def test_the_paper_difference_is_the_reference_at_step_5_only():
    table1 = report.PAPER['table1']
    assert stats_report.step_reference('5%', 5, table1) == pytest.approx(0.0325)
    assert stats_report.step_reference('10%', 5, table1) == pytest.approx(0.0129)
    assert stats_report.step_reference('5%', 3, table1) is None
    assert stats_report.step_reference('20%', 5, table1) is None


def test_the_analysis_judges_every_step_and_the_generation_of_the_best():
    results = synthetic()
    analysis = report.analyse(results, None)
    assert analysis['statistics'] == {'alpha': 0.05, 'target': 0.8, 'margin': 0.032}
    for test in analysis['tests']:
        level = next(lv for lv in results.config.levels if lv.label == test['level'])
        combo, indep = level.conditions
        a, b = results.scores(combo, test['step']), results.scores(indep, test['step'])
        assert test['comparison'] == dataclasses.asdict(stats.compare(a, b))
        assert test['verdict']['kind'] in verdict.KINDS
    step5 = next(t for t in analysis['tests'] if t['level'] == '5%' and t['step'] == 5)
    assert step5['reference'] == pytest.approx(0.0325)
    assert step5['verdict']['kind'] == 'difference'          # synthetic: 0.80 vs 0.76
    gen = analysis['best_generation'][0]
    assert gen['comparison']['equivalence']['margin'] == pytest.approx(7.8)
    assert gen['verdict']['text'].startswith('combination sooner by')
    finding = next(f for f in analysis['findings'] if 'final real test' in f['claim'])
    assert step5['verdict']['text'] in finding['ours']


def test_the_report_has_a_table_per_level_the_generation_and_the_power_section():
    results = synthetic()
    analysis = report.analyse(results, None)
    text = report.markdown(results.config, analysis, {'simulation': 's', 'reality': 'r'},
                           [{'elapsed_s': 1.0}])
    for level in results.config.levels:
        tests = [t for t in analysis['tests'] if t['level'] == level.label]
        table = stats_report.level_table(level.label, tests, STEPS)
        assert table in text
        rows = [line for line in table.splitlines() if line.startswith('| ') and
                line[2].isdigit()]
        assert len(rows) == len(STEPS)
        for t, row in zip(tests, rows):
            c = t['comparison']['interval']
            assert f"{c['difference']:+.3f} [{c['ci_low']:.3f}, {c['ci_high']:.3f}]" in row
            assert f"**{t['verdict']['kind']}**" in row
            assert f"- Step {t['step']}: {t['verdict']['text']}." in table
    assert '| 5 | test in reality | 0.795 vs 0.763, p < 0.05 |' in text
    assert '| 5% | generation of the best | 35.0 vs 42.8, p < 0.05 |' in text
    assert '## Power: what this design can detect' in text
    sd = pw.pooled_sd(*(results.scores(c, 5).std(ddof=1)
                        for c in results.config.levels[0].conditions))
    plan = pw.plan(sd, 10)
    assert (f'| {sd:.3f} | measured: 5% step 5 | 10 | {plan.mdd:.3f} | {plan.power:.0%} | '
            f'{plan.trials_needed} |') in text
    assert 'at most 0.024' in text and 'at most 0.034' in text


def test_the_power_analysis_before_a_run_uses_assumed_and_measured_spreads(tmp_path):
    config = tiny(trials=4)
    text = stats_report.power_before_run(config)
    for sd in pw.ASSUMED_SDS:
        p = pw.plan(sd, 4)
        assert f'| {sd:.3f} | assumed | 4 | {p.mdd:.3f} | {p.power:.0%} | ' \
               f'{p.trials_needed} |' in text
    assert 'measured' not in text
    store = Store(tmp_path, config.hash)
    store.open(config.to_yaml())
    assert 'measured' not in stats_report.power_before_run(config, store)   # nothing yet
    scores = {'combination': [0.80, 0.76, 0.78], 'independent': [0.70, 0.74]}
    for c in config.levels[0].conditions:
        for t, score in enumerate(scores[c.model]):
            store.save(c.key, t, 5, {'mean': score})
    text = stats_report.power_before_run(config, store)
    sd = pw.pooled_sd(np.std(scores['combination'], ddof=1),
                      np.std(scores['independent'], ddof=1))
    assert f'| {sd:.3f} | measured: 5% step 5, 2 trials | 4 |' in text
    assert 'measured: 10%' not in text               # no finished tests at 10% yet


def test_replicate_prints_the_power_analysis_before_it_runs(tmp_path, capsys):
    path = tmp_path / 'tiny.yaml'
    path.write_text(yaml.safe_dump({
        'trials': 2, 'test_episodes': 1, 'phase1': {'population': 3, 'generations': 1},
        'phase2': {'population': 2, 'generations': 1}, 'task': {'steps': 5},
        'reality': {'robots': 4}}))
    out = tmp_path / 'run'
    assert cli.main(['replicate', '--config', str(path), '--out', str(out), '--backend',
                     'core', '--no-progress']) == 0
    printed = capsys.readouterr().out
    assert printed.startswith('Power analysis (before the run): step 5, 2 trials per model')
    assert printed.index('Power analysis') < printed.index('Table 1')
    assert '## Power: what this design can detect' in (out / 'report.md').read_text()


def test_a_step_without_spread_is_reported_as_such_not_as_a_crash():
    results = synthetic()
    for (key, t, step), unit in results.units.items():
        unit['best_generation'] = 40
        if key.startswith('10pct') and step == 2:
            unit['mean'] = 0.7
    analysis = report.analyse(results, None)
    json.dumps(analysis)
    text = report.markdown(results.config, analysis, {}, [{'elapsed_s': 1.0}])
    assert ('| 2 | test in simulation | similar | 0.700 ± 0.000 | 0.700 ± 0.000 | +0.000 | '
            'n/a | n/a | 1.000 (0.50) | n/a (± 0.032) | **no spread** |') in text
    assert '- 5%: no test: every trial within each model scored the same (40.0 vs 40.0).' in text


def test_kinds_text_groups_the_steps_by_verdict():
    tests = [{'step': s, 'verdict': {'kind': k}} for s, k in
             ((1, 'equivalent'), (2, 'equivalent'), (3, 'underpowered'))]
    assert stats_report.kinds_text(tests) == 'equivalent at steps 1, 2; underpowered at step 3'


def test_a_finding_the_design_cannot_test_is_called_underpowered_not_differs():
    results = synthetic()
    z = np.linspace(-1, 1, 10)
    z = (z - z.mean()) / z.std(ddof=1)
    for (key, t, step), unit in results.units.items():
        if step == 5 and key.startswith('5pct'):       # SD 0.06, combination 0.005 worse
            unit['mean'] = 0.76 - 0.005 * ('combination' in key) + 0.06 * z[t]
    analysis = report.analyse(results, None)
    step5 = next(t for t in analysis['tests'] if t['level'] == '5%' and t['step'] == 5)
    assert step5['verdict']['kind'] == 'underpowered'
    finding = next(f for f in analysis['findings'] if 'final real test' in f['claim'])
    assert finding['verdict'] == 'underpowered'
    assert 'underpowered (our interval admits the effect and none)' in report.summary(analysis)
    ten = next(f for f in analysis['findings'] if f['claim'].startswith('10%'))
    level = [t for t in analysis['tests'] if t['level'] == '10%']
    assert ten['ours'].endswith(stats_report.kinds_text(level))
