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
