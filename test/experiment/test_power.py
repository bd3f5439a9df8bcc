"""Power analysis against statsmodels and against simulated t-tests."""
import math

import numpy as np
import pytest
from scipy import stats as sps
from statsmodels.stats.power import TTestIndPower

from khepera_noise_ros.experiment import power as pw

SM = TTestIndPower()


@pytest.mark.parametrize('difference, sd, n', [(0.032, 0.03, 10), (0.032, 0.05, 10),
                                               (0.032, 0.08, 40), (0.01, 0.02, 7),
                                               (-0.05, 0.04, 3)])
def test_power_matches_statsmodels(difference, sd, n):
    expected = SM.power(effect_size=difference / sd, nobs1=n, alpha=0.05, ratio=1.0,
                        alternative='two-sided')
    assert pw.power(difference, sd, n) == pytest.approx(expected, rel=1e-9)


@pytest.mark.parametrize('sd, n, alpha, target', [(0.03, 10, 0.05, 0.8), (0.05, 10, 0.05, 0.8),
                                                  (0.05, 25, 0.01, 0.9), (1.0, 4, 0.05, 0.5)])
def test_minimum_detectable_difference_matches_statsmodels(sd, n, alpha, target):
    effect = SM.solve_power(effect_size=None, nobs1=n, alpha=alpha, power=target)
    mdd = pw.minimum_detectable_difference(sd, n, alpha, target)
    assert mdd == pytest.approx(effect * sd, rel=1e-6)
    assert pw.power(mdd, sd, n, alpha) == pytest.approx(target, abs=1e-9)


@pytest.mark.parametrize('sd', [0.02, 0.03, 0.05, 0.08, 0.19])
def test_trials_needed_is_the_smallest_n_with_enough_power(sd):
    n = pw.trials_needed(0.032, sd)
    assert pw.power(0.032, sd, n) >= 0.8
    assert n == 2 or pw.power(0.032, sd, n - 1) < 0.8
    exact = SM.solve_power(effect_size=0.032 / sd, nobs1=None, alpha=0.05, power=0.8)
    assert n == math.ceil(exact)


def test_welch_power_with_unequal_spreads_agrees_with_simulated_welch_tests():
    rng = np.random.default_rng(12)
    a = rng.normal(0.795, 0.03, size=(20000, 12))
    b = rng.normal(0.763, 0.07, size=(20000, 8))
    hits = (sps.ttest_ind(a, b, axis=1, equal_var=False).pvalue < 0.05).mean()
    predicted = pw.power(0.032, 0.03, 12, sd_b=0.07, n_b=8)
    assert predicted == pytest.approx(hits, abs=0.015)
    # and it is not simply the equal-spread answer
    assert abs(pw.power(0.032, 0.03, 12) - hits) > 0.1


def test_power_of_no_difference_is_alpha_and_grows_with_difference_and_trials():
    assert pw.power(0.0, 0.05, 10) == pytest.approx(0.05, abs=1e-12)
    assert pw.power(0.0, 0.05, 10, alpha=0.01) == pytest.approx(0.01, abs=1e-12)
    assert pw.power(0.02, 0.05, 10) < pw.power(0.04, 0.05, 10) < pw.power(0.04, 0.05, 30)


@pytest.mark.parametrize('sd', [0.016, 0.017, 0.012])
def test_power_far_in_the_tail_is_a_number(sd):
    """Fifty trials at the sweep's spreads: scipy's noncentral t (and statsmodels with it)
    gave NaN there; the power is then above that of a larger spread, and at most 1."""
    p = pw.power(0.032, sd, 50)
    wider = SM.power(effect_size=0.032 / 0.02, nobs1=50, alpha=0.05, ratio=1.0,
                     alternative='two-sided')
    assert math.isfinite(wider) and pw.power(0.032, 0.02, 50) == pytest.approx(wider)
    assert math.isfinite(p) and wider < p <= 1.0
    assert pw.power(-0.032, sd, 50) == pytest.approx(p, abs=1e-12)


def test_largest_sd_gives_exactly_the_target_power():
    sd = pw.largest_sd(0.032, 10)
    assert pw.power(0.032, sd, 10) == pytest.approx(0.8, abs=1e-9)
    assert pw.trials_needed(0.032, sd * 1.01) > 10 >= pw.trials_needed(0.032, sd * 0.99)


def test_significant_below_is_where_an_observed_difference_turns_significant():
    sd = pw.significant_below(0.032, 10)
    z = np.array([-1.5, -1.0, -0.6, -0.3, 0.0, 0.1, 0.3, 0.6, 1.0, 1.4])
    z = (z - z.mean()) / z.std(ddof=1)            # exactly mean 0, SD 1
    for factor, significant in ((0.999, True), (1.001, False)):
        a, b = 0.795 + factor * sd * z, 0.763 + factor * sd * z
        assert bool(sps.ttest_ind(a, b, equal_var=False).pvalue < 0.05) is significant


def test_plan_collects_the_design_figures_and_the_table_shows_them():
    p = pw.plan(0.05, 10)
    assert (p.sd, p.n, p.difference, p.alpha, p.target) == (0.05, 10, 0.032, 0.05, 0.8)
    assert p.mdd == pw.minimum_detectable_difference(0.05, 10)
    assert p.power == pw.power(0.032, 0.05, 10)
    assert p.trials_needed == pw.trials_needed(0.032, 0.05)
    table = pw.plan_table([p, pw.plan(0.03, 10, source='measured: x')], "the paper's 0.032")
    lines = table.splitlines()
    assert len(lines) == 4 and "Power for the paper's 0.032" in lines[0]
    assert lines[2] == (f'| 0.050 | assumed | 10 | {p.mdd:.3f} | {p.power:.0%} | '
                        f'{p.trials_needed} |')
    assert 'measured: x' in lines[3]


def test_pooled_sd_is_the_root_mean_square():
    assert pw.pooled_sd(0.03, 0.04) == pytest.approx(math.sqrt(0.00125))


@pytest.mark.parametrize('call, match', [
    (lambda: pw.power(0.03, 0.0, 10), r'sd must be a finite number > 0, got 0\.0'),
    (lambda: pw.power(0.03, float('nan'), 10), 'sd must be a finite number'),
    (lambda: pw.power(0.03, 0.05, 1), 'n must be an integer >= 2, got 1'),
    (lambda: pw.power(0.03, 0.05, 10.5), 'n must be an integer >= 2, got 10.5'),
    (lambda: pw.power(0.03, 0.05, True), 'n must be an integer'),
    (lambda: pw.power(0.03, 0.05, 10, alpha=1.5), 'alpha must be a finite number > 0 and < 1'),
    (lambda: pw.minimum_detectable_difference(0.05, 10, target=0.01), 'target must be'),
    (lambda: pw.trials_needed(0.0, 0.05), 'difference must be non-zero'),
    (lambda: pw.trials_needed(1e-9, 10.0), 'needs more than'),
    (lambda: pw.largest_sd(0.0, 10), 'difference must be non-zero'),
])
def test_bad_designs_are_refused_with_one_line(call, match):
    with pytest.raises(ValueError, match=match) as info:
        call()
    assert '\n' not in str(info.value)
