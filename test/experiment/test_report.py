"""The analysis and the report: numbers against scipy, verdicts against the paper, files."""
import csv
import json

import numpy as np
import pytest
from scipy import stats as sps

from khepera_noise_ros.experiment import config as settings
from khepera_noise_ros.experiment import recovery, report
from khepera_noise_ros.experiment.protocol import STEPS
from khepera_noise_ros.testing.experiments import TINY, backends, run, synthetic, tiny


def with_ceiling(results: report.Results, gain: float) -> report.Results:
    """``results`` with a ceiling arm whose final test is step 3 + ``gain`` (+ noise)."""
    config = settings.load(overrides={**TINY, 'trials': results.config.trials,
                                      'ceiling': {'enabled': True}})
    rng = np.random.default_rng(9)
    units = dict(results.units)
    for c in config.conditions:
        for t in range(config.trials):
            value = units[c.key, t, 3]['mean'] + gain + rng.normal(0, 0.01)
            units[c.key, t, 6] = {'best_fitness': value, 'mean': value, 'world': 'x'}
            units[c.key, t, 7] = {'best_fitness': value, 'mean': value, 'world': 'x'}
    return report.Results(config, units)


def test_the_drop_and_its_recovery_are_paired_differences_with_t_intervals():
    results = with_ceiling(synthetic(), gain=0.15)
    rec = recovery.recovery(results)
    for c in results.config.conditions:
        drop = results.scores(c, 2) - results.scores(c, 3)
        row = rec['rows'][c.name]
        assert row['drop']['mean'] == pytest.approx(drop.mean())
        assert (row['drop']['ci_low'], row['drop']['ci_high']) == pytest.approx(
            sps.t.interval(0.95, drop.size - 1, drop.mean(), sps.sem(drop)))
        back = results.scores(c, 7) - results.scores(c, 3)
        assert row['ceiling']['mean'] == pytest.approx(back.mean())
    every = rec['rows'][recovery.ALL]
    assert every['drop']['n'] == results.config.trials * len(results.config.conditions)
    text = recovery.recovery_md(results.config, rec)
    assert 'ceiling arm' in text and 'had room to show it' in text
    flat = recovery.recovery_md(results.config, recovery.recovery(
        with_ceiling(synthetic(), gain=0.0)))
    assert 'bound to come out flat' in flat
    plain = recovery.recovery_md(results.config, recovery.recovery(synthetic()))
    assert '--ceiling' in plain and 'Ceiling step 5' not in plain


def test_table1_is_ranked_with_mean_sd_and_ci():
    results = synthetic()
    analysis = report.analyse(results, None)
    rows = analysis['table1']
    assert [r['rank'] for r in rows] == [1, 2, 3, 4]
    assert [r['mean'] for r in rows] == sorted((r['mean'] for r in rows), reverse=True)
    for r in rows:
        c = next(c for c in results.config.conditions if c.name == r['condition'])
        x = results.scores(c, 5)
        assert r['mean'] == pytest.approx(x.mean()) and r['sd'] == pytest.approx(x.std(ddof=1))
        assert r['ci'] == pytest.approx(list(sps.t.interval(0.95, 9, x.mean(), sps.sem(x))))
        assert r['paper'] == report.PAPER['table1'][r['condition']]


def test_each_step_is_tested_with_welch_against_scipy():
    results = synthetic()
    analysis = report.analyse(results, None)
    assert len(analysis['tests']) == 2 * len(STEPS)
    for test in analysis['tests']:
        level = next(lv for lv in results.config.levels if lv.label == test['level'])
        combo, indep = level.conditions
        ref = sps.ttest_ind(results.scores(combo, test['step']),
                            results.scores(indep, test['step']), equal_var=False)
        assert (test['t'], test['df'], test['p']) == pytest.approx(
            (ref.statistic, ref.df, ref.pvalue), rel=1e-12)
    gen = analysis['best_generation'][0]
    assert gen['level'] == '5%' and gen['paper'] == {'combination': 35.0, 'independent': 42.8}
    assert gen['mean_a'] == pytest.approx(30.0, abs=1) and gen['p'] < 0.05


def finding(analysis, text) -> dict:
    return next(f for f in analysis['findings'] if text in f['claim'])


def test_verdicts_follow_the_numbers():
    analysis = report.analyse(synthetic(), None)
    assert finding(analysis, 'final real test')['verdict'] == 'agrees'   # 0.80 vs 0.76
    assert finding(analysis, 'best fitness sooner')['verdict'] == 'agrees'   # 30 vs 44
    assert finding(analysis, 'real training')['verdict'] == 'agrees'    # 3 < 4 < 1
    assert finding(analysis, 'ranking')['verdict'] == 'agrees'          # the paper's order
    swapped = synthetic()
    for (key, t, s), unit in swapped.units.items():
        if key == '5pct-independent' and s == 5:
            unit['mean'] += 0.1
    again = report.analyse(swapped, None)
    assert finding(again, 'final real test')['verdict'] == 'differs'
    assert finding(again, 'ranking')['verdict'] == 'differs'
    close = synthetic()
    for t in range(10):                  # combination ahead by a hair: the sign, not the p
        close.units['5pct-combination', t, 5]['mean'] = \
            close.units['5pct-independent', t, 5]['mean'] + 0.02 * (t % 2)
    tied = report.analyse(close, None)
    assert finding(tied, 'final real test')['verdict'] == 'same direction, not significant'
    assert 'in the same direction but not significant' in report.summary(tied)


def test_a_run_writes_the_report_the_figures_and_the_raw_results(tmp_path):
    config = tiny()
    store, _ = run(config, tmp_path, backends=backends(config, traced=True))
    out = tmp_path / 'out'
    analysis = report.write(out, config, store, {'simulation': 'sim', 'reality': 'real'},
                            [{'elapsed_s': 2.0, 'finished': True}])
    for name in ('report.md', 'results.json', 'results.csv', 'fig8.png', 'fig9.png',
                 'fig10.png', 'curves.png', 'config.yaml'):
        assert (out / name).stat().st_size > 0, name
    text = (out / 'report.md').read_text()
    for needle in ('0.7952', '0.7567', '0.818', '35.0 vs 42.8', "Welch's t-test",
                   '![fig9](fig9.png)', 'emulator', config.hash):
        assert needle in text, needle
    with (out / 'results.csv').open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(config.conditions) * config.trials * len(STEPS)
    assert tuple(rows[0]) == report.CSV_COLUMNS
    data = json.loads((out / 'results.json').read_text())
    assert data['format'] == report.RESULTS_FORMAT and data['config_hash'] == config.hash
    assert len(data['units']) == len(rows)
    first = rows[0]
    unit = store.load(config.conditions[0].key, 0, 1)
    assert float(first['score']) == unit['best_fitness']
    assert analysis['figure8']['mean'] == pytest.approx(np.mean(analysis['figure8']['fitness']))
    assert report.summary(analysis).startswith('Table 1')


def test_an_unfinished_run_has_no_report(tmp_path):
    from khepera_noise_ros.experiment.store import Store
    config = tiny()
    store = Store(tmp_path, config.hash)
    store.open(config.to_yaml())
    with pytest.raises(RuntimeError, match='5% combination trial 1 step 1 is not finished'):
        report.collect(config, store)
