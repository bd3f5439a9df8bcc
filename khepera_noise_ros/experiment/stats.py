"""Summaries and t-tests for the comparisons of section 4.4.

The paper says only that the trial averages were "compared using t-tests".
We use Welch's two-sample t-test (scipy's ``ttest_ind(equal_var=False)``),
two-sided: the two noise models need not give the same spread of results
across trials (the independent model's real-world scores can scatter more),
and Welch's test does not assume they do.  With equal group sizes its t is
the same as Student's; only the degrees of freedom (Welch-Satterthwaite,
fractional) and hence p differ slightly.  Student's test is available too.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
from scipy import stats

CONFIDENCE = 0.95


@dataclass(frozen=True)
class Summary:
    n: int
    mean: float
    sd: float             # sample standard deviation (n - 1)
    ci_low: float         # t-based confidence interval of the mean
    ci_high: float


@dataclass(frozen=True)
class TTest:
    test: str             # "Welch's t-test" or "Student's t-test", two-sided
    t: float
    df: float
    p: float
    mean_a: float
    mean_b: float
    n_a: int
    n_b: int


def _sample(values, name: str) -> np.ndarray:
    x = np.asarray(values, dtype=np.float64).reshape(-1)
    if x.size == 0 or not np.isfinite(x).all():
        raise ValueError(f'{name} must be a non-empty list of finite numbers, got {values!r}')
    return x


def summarize(values, confidence: float = CONFIDENCE) -> Summary:
    """Mean, SD and the ``confidence`` interval of the mean (NaN spread for one value)."""
    x = _sample(values, 'values')
    mean = float(x.mean())
    if x.size < 2:
        return Summary(1, mean, math.nan, math.nan, math.nan)
    sd = float(x.std(ddof=1))
    half = float(stats.t.ppf(0.5 + confidence / 2, x.size - 1)) * sd / math.sqrt(x.size)
    return Summary(int(x.size), mean, sd, mean - half, mean + half)


def ttest(a, b, equal_var: bool = False) -> TTest:
    """Two-sided two-sample t-test of a against b: Welch's unless ``equal_var``."""
    a, b = _sample(a, 'a'), _sample(b, 'b')
    if a.size < 2 or b.size < 2:
        raise ValueError(f'a t-test needs at least 2 values per group, got {a.size} and {b.size}')
    with warnings.catch_warnings():     # nearly constant groups: t is still defined
        warnings.simplefilter('ignore', RuntimeWarning)
        result = stats.ttest_ind(a, b, equal_var=equal_var)
    name = "Student's t-test" if equal_var else "Welch's t-test"
    return TTest(name, float(result.statistic), float(result.df), float(result.pvalue),
                 float(a.mean()), float(b.mean()), int(a.size), int(b.size))


def rank_test(a, b) -> float:
    """Two-sided Mann-Whitney U p-value: a check on the t-test that a few collapsed
    trials (outliers far below the rest) cannot drive."""
    a, b = _sample(a, 'a'), _sample(b, 'b')
    return float(stats.mannwhitneyu(a, b, alternative='two-sided').pvalue)


def power(difference: float, sd: float, n: int, alpha: float = 0.05) -> float:
    """Chance that a two-sided t-test at ``alpha`` detects a true ``difference`` of means.

    Two groups of ``n`` with common standard deviation ``sd`` (Student's
    test; Welch's is nearly the same for equal groups): the noncentral t.
    """
    if n < 2 or not sd > 0:
        raise ValueError(f'power needs n >= 2 and sd > 0, got n={n}, sd={sd}')
    df = 2 * n - 2
    shift = difference / (sd * math.sqrt(2.0 / n))
    critical = stats.t.ppf(1 - alpha / 2, df)
    return float(stats.nct.sf(critical, df, shift) + stats.nct.cdf(-critical, df, shift))


def describe(test: TTest) -> str:
    """'t(17.6) = 2.31, p = 0.033' in the usual reporting form."""
    if not math.isfinite(test.t):
        return 'no test (both groups constant)'
    p = f'p = {test.p:.3f}' if test.p >= 0.001 else 'p < 0.001'
    return f't({test.df:.1f}) = {test.t:.2f}, {p}'
