"""The statistics of the report against scipy and against the textbook formulas."""
import math

import numpy as np
import pytest
from scipy import stats as sps

from khepera_noise_ros.experiment import stats

# Two samples of unequal size and spread, so Welch's and Student's tests differ.
A = [0.801, 0.774, 0.812, 0.790, 0.768, 0.799, 0.805, 0.781, 0.795, 0.788]
B = [0.742, 0.781, 0.705, 0.760, 0.799, 0.731, 0.752]


def test_summary_matches_scipy_t_interval():
    s = stats.summarize(A)
    low, high = sps.t.interval(0.95, len(A) - 1, loc=np.mean(A), scale=sps.sem(A))
    assert s.n == 10
    assert s.mean == pytest.approx(np.mean(A), abs=1e-15)
    assert s.sd == pytest.approx(np.std(A, ddof=1), abs=1e-15)
    assert (s.ci_low, s.ci_high) == pytest.approx((low, high), abs=1e-12)


def test_welch_matches_the_welch_satterthwaite_formulas_and_scipy():
    t = stats.ttest(A, B)
    va, vb = np.var(A, ddof=1) / len(A), np.var(B, ddof=1) / len(B)
    t_hand = (np.mean(A) - np.mean(B)) / math.sqrt(va + vb)
    df_hand = (va + vb) ** 2 / (va ** 2 / (len(A) - 1) + vb ** 2 / (len(B) - 1))
    assert t.test == "Welch's t-test"
    assert t.t == pytest.approx(t_hand, rel=1e-12)
    assert t.df == pytest.approx(df_hand, rel=1e-12)
    assert t.p == pytest.approx(2 * sps.t.sf(abs(t_hand), df_hand), rel=1e-9)
    ref = sps.ttest_ind(A, B, equal_var=False)
    assert (t.t, t.p) == pytest.approx((ref.statistic, ref.pvalue), rel=1e-12)
    assert (t.n_a, t.n_b) == (10, 7)


def test_student_uses_the_pooled_variance():
    t = stats.ttest(A, B, equal_var=True)
    pooled = ((len(A) - 1) * np.var(A, ddof=1) + (len(B) - 1) * np.var(B, ddof=1)) / 15
    t_hand = (np.mean(A) - np.mean(B)) / math.sqrt(pooled * (1 / 10 + 1 / 7))
    assert t.test == "Student's t-test"
    assert t.df == 15
    assert t.t == pytest.approx(t_hand, rel=1e-12)
    assert t.p == pytest.approx(2 * sps.t.sf(abs(t_hand), 15), rel=1e-9)


def test_power_matches_the_classic_table():
    # Cohen: d = 1 with 17 per group gives about 80% power at alpha 0.05, two-sided.
    assert stats.power(1.0, 1.0, 17) == pytest.approx(0.807, abs=0.002)
    assert stats.power(0.0, 1.0, 10) == pytest.approx(0.05, abs=1e-9)
    assert stats.power(0.5, 0.1, 10) > 0.999


def test_power_agrees_with_simulated_t_tests():
    rng = np.random.default_rng(3)
    a = rng.normal(0.03, 0.04, size=(4000, 10))
    b = rng.normal(0.0, 0.04, size=(4000, 10))
    hits = (sps.ttest_ind(a, b, axis=1).pvalue < 0.05).mean()
    assert stats.power(0.03, 0.04, 10) == pytest.approx(hits, abs=0.03)


def test_single_value_has_no_spread():
    s = stats.summarize([0.7])
    assert s.mean == 0.7 and math.isnan(s.sd) and math.isnan(s.ci_low)


@pytest.mark.parametrize('a, b, match', [([], [1, 2], 'non-empty'),
                                         ([1, float('nan')], [1, 2], 'finite'),
                                         ([1], [1, 2], 'at least 2')])
def test_bad_samples_are_refused(a, b, match):
    with pytest.raises(ValueError, match=match):
        stats.ttest(a, b)


def test_describe_reports_t_df_and_p():
    t = stats.ttest(A, B)
    assert stats.describe(t) == f't({t.df:.1f}) = {t.t:.2f}, p = {t.p:.3f}'
    assert stats.describe(stats.ttest([1.0, 1.1, 0.9], [5.0, 5.1, 4.9])).endswith('p < 0.001')
    assert stats.describe(stats.ttest([1, 1], [1, 1])).startswith('no test')


def test_rank_test_is_scipys_two_sided_mann_whitney():
    expected = sps.mannwhitneyu(A, B, alternative='two-sided').pvalue
    assert stats.rank_test(A, B) == pytest.approx(expected, rel=1e-12)
    # one collapsed trial moves the t-test far more than the rank test
    collapsed = B[:-1] + [0.05]
    assert stats.ttest(A, collapsed).p > stats.rank_test(A, collapsed)


# --- the difference, its interval and its effect size ---------------------------------------

@pytest.mark.parametrize('confidence', [0.95, 0.90, 0.99])
def test_welch_interval_is_scipys(confidence):
    ci = stats.welch_interval(A, B, confidence)
    ref = sps.ttest_ind(A, B, equal_var=False).confidence_interval(confidence)
    assert (ci.ci_low, ci.ci_high) == pytest.approx((ref.low, ref.high), rel=1e-12)
    assert ci.difference == pytest.approx(np.mean(A) - np.mean(B), abs=1e-15)
    assert ci.se == pytest.approx(math.sqrt(np.var(A, ddof=1) / 10 + np.var(B, ddof=1) / 7))
    assert ci.df == pytest.approx(stats.ttest(A, B).df, rel=1e-12)


def test_hedges_g_is_the_corrected_standardized_difference():
    e = stats.hedges_g(A, B)
    pooled = math.sqrt((9 * np.var(A, ddof=1) + 6 * np.var(B, ddof=1)) / 15)
    d = (np.mean(A) - np.mean(B)) / pooled
    assert e.d == pytest.approx(d, rel=1e-12)
    # the exact J against Hedges' approximation 1 - 3 / (4 df - 1), close at df = 15
    assert e.g == pytest.approx(d * (1 - 3 / (4 * 15 - 1)), rel=1e-3)
    assert e.g < e.d and e.ci_low < e.g < e.ci_high
    # the ends are where the observed t is the 97.5% and 2.5% point of the noncentral t
    scale = math.sqrt(1 / 10 + 1 / 7)
    t = d / scale
    assert sps.nct.cdf(t, 15, e.ci_low / scale) == pytest.approx(0.975, abs=1e-8)
    assert sps.nct.cdf(t, 15, e.ci_high / scale) == pytest.approx(0.025, abs=1e-8)


def test_hedges_g_interval_covers_the_true_effect_95_percent_of_the_time():
    rng = np.random.default_rng(1998)
    covered = [stats.hedges_g(rng.normal(0.8, 1, 10), rng.normal(0, 1, 10))
               for _ in range(500)]
    rate = np.mean([e.ci_low <= 0.8 <= e.ci_high for e in covered])
    assert rate == pytest.approx(0.95, abs=0.025)


def test_mann_whitney_superiority_is_the_share_of_pairs_won():
    r = stats.mann_whitney(A, B + [0.790])          # a tie with A's 0.790 counts half
    b = B + [0.790]
    wins = sum((x > y) + 0.5 * (x == y) for x in A for y in b)
    assert r.superiority == pytest.approx(wins / (len(A) * len(b)), abs=1e-12)
    assert r.p == pytest.approx(sps.mannwhitneyu(A, b, alternative='two-sided').pvalue)
    assert stats.mann_whitney(B, A).superiority == pytest.approx(1 - stats.mann_whitney(
        A, B).superiority)


# --- equivalence ------------------------------------------------------------------------------

@pytest.mark.parametrize('margin', [0.032, 0.05, 0.01])
def test_tost_matches_statsmodels_welch_ttost(margin):
    from statsmodels.stats.weightstats import ttost_ind
    e = stats.tost(A, B, margin)
    p, lower, upper = ttost_ind(A, B, -margin, margin, usevar='unequal')
    assert (e.p, e.p_lower, e.p_upper) == pytest.approx((p, lower[1], upper[1]), rel=1e-9)


def test_tost_finds_equivalence_only_for_close_samples():
    rng = np.random.default_rng(4)
    same = rng.normal(0.78, 0.01, 30), rng.normal(0.78, 0.01, 30)
    apart = rng.normal(0.82, 0.01, 30), rng.normal(0.76, 0.01, 30)
    assert stats.tost(*same).equivalent and stats.tost(*same).p < 0.001
    assert not stats.tost(*apart).equivalent and stats.tost(*apart).p > 0.99
    # few noisy trials: neither different nor equivalent
    few = rng.normal(0.78, 0.05, 5), rng.normal(0.78, 0.05, 5)
    assert not stats.tost(*few).equivalent


def test_tost_is_the_90_percent_interval_inside_the_margin():
    rng = np.random.default_rng(7)
    for _ in range(200):
        a, b = rng.normal(0.01, 0.02, 12), rng.normal(0, 0.03, 9)
        e = stats.tost(a, b, 0.03)
        ci = stats.welch_interval(a, b, 0.90)
        assert (e.ci_low, e.ci_high) == pytest.approx((ci.ci_low, ci.ci_high), rel=1e-12)
        assert e.equivalent == (-0.03 < ci.ci_low and ci.ci_high < 0.03)
        assert e.bound == pytest.approx(max(abs(ci.ci_low), abs(ci.ci_high)))


# --- compare, and what it does with degenerate samples ------------------------------------------

def test_compare_gathers_every_estimate_and_test():
    c = stats.compare(A, B, margin=0.02)
    assert c.spread and c.alpha == 0.05
    assert c.a == stats.summarize(A) and c.b == stats.summarize(B)
    assert c.interval == stats.welch_interval(A, B)
    assert c.welch == stats.ttest(A, B)
    assert c.effect == stats.hedges_g(A, B)
    assert c.rank == stats.mann_whitney(A, B)
    assert c.equivalence == stats.tost(A, B, 0.02)


def test_one_constant_group_is_still_compared():
    c = stats.compare([0.7] * 5, [0.60, 0.62, 0.64, 0.66, 0.68])
    assert c.spread and c.interval.difference == pytest.approx(0.06)
    assert c.interval.ci_low > 0 and math.isfinite(c.effect.g)


def test_groups_without_spread_are_compared_explicitly_and_refused_by_each_test():
    c = stats.compare([0.7, 0.7, 0.7], [0.7, 0.7])
    assert not c.spread and c.interval.difference == 0
    undefined = (c.interval.ci_low, c.welch.p, c.effect.g, c.equivalence.p)
    assert all(math.isnan(x) for x in undefined)
    assert c.rank.p == 1.0 and not c.equivalence.equivalent
    for call in (stats.welch_interval, stats.hedges_g, stats.tost):
        with pytest.raises(ValueError, match='no spread within either group') as info:
            call([0.7, 0.7], [0.6, 0.6])
        assert '\n' not in str(info.value)


@pytest.mark.parametrize('call, match', [
    (lambda: stats.compare([0.7], [0.6, 0.7]), 'at least 2 values per group, got 1 and 2'),
    (lambda: stats.compare([0.7, math.nan], [0.6, 0.7]), 'finite numbers'),
    (lambda: stats.compare([0.7, 0.8], []), 'non-empty'),
    (lambda: stats.hedges_g([0.7], [0.6, 0.7]), 'at least 2'),
    (lambda: stats.tost(A, B, margin=0), 'margin must be a number > 0, got 0'),
    (lambda: stats.tost(A, B, margin=math.inf), 'margin must be a number > 0'),
    (lambda: stats.compare(A, B, alpha=1.2), 'alpha must be between 0 and 1, got 1.2'),
    (lambda: stats.welch_interval(A, B, confidence=95), 'confidence must be between 0 and 1'),
    (lambda: stats.mann_whitney([math.inf], B), 'finite'),
])
def test_degenerate_input_is_refused_with_one_line(call, match):
    with pytest.raises(ValueError, match=match) as info:
        call()
    assert '\n' not in str(info.value)


def test_p_text():
    assert stats.p_text(0.0331) == 'p = 0.033'
    assert stats.p_text(0.0004) == 'p < 0.001'
    assert stats.p_text(math.nan) == 'p n/a'
