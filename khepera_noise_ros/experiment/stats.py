"""Estimates and tests for the comparisons of section 4.4: what the data can say.

For two samples (combination, independent): the difference of means with its
Welch confidence interval, Hedges' g with its exact interval, Welch's t-test,
the Mann-Whitney test with the probability of superiority, and the equivalence
test (TOST) against a stated margin.  ``verdict.judge`` phrases the result;
docs/statistics.md gives the formulas and the reasons.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
from scipy import optimize, special, stats

from .power import PAPER_DIFFERENCE, power  # noqa: F401  (power: the API it always had)

CONFIDENCE = 0.95
ALPHA = 0.05


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


@dataclass(frozen=True)
class Interval:
    """The difference of means (a - b) and its Welch confidence interval."""

    difference: float
    ci_low: float
    ci_high: float
    confidence: float
    se: float             # standard error of the difference, sqrt(s_a^2/n_a + s_b^2/n_b)
    df: float             # Welch-Satterthwaite degrees of freedom


@dataclass(frozen=True)
class EffectSize:
    """Hedges' g: the difference in pooled SDs, small-sample corrected; the exact CI of the
    population's standardized difference (delta)."""

    g: float
    ci_low: float
    ci_high: float
    d: float              # Cohen's d, uncorrected


@dataclass(frozen=True)
class RankTest:
    """Two-sided Mann-Whitney U; ``superiority`` = P(a > b) + P(a = b) / 2 over all pairs."""

    u: float
    p: float
    superiority: float


@dataclass(frozen=True)
class Equivalence:
    """Welch TOST: is |a - b| < margin?  ``equivalent`` when p < alpha."""

    margin: float
    p: float              # max of the two one-sided p values
    p_lower: float        # H0: difference <= -margin
    p_upper: float        # H0: difference >= +margin
    ci_low: float         # the 1 - 2 alpha interval the test amounts to
    ci_high: float
    bound: float          # the smallest margin this interval supports: max |end|
    alpha: float
    equivalent: bool


@dataclass(frozen=True)
class Comparison:
    """Everything ``compare`` finds for two samples; NaN where no spread leaves it undefined."""

    a: Summary
    b: Summary
    interval: Interval
    welch: TTest
    effect: EffectSize
    rank: RankTest
    equivalence: Equivalence
    alpha: float
    spread: bool          # False: every value within each group is the same; no test


def _sample(values, name: str) -> np.ndarray:
    x = np.asarray(values, dtype=np.float64).reshape(-1)
    if x.size == 0 or not np.isfinite(x).all():
        raise ValueError(f'{name} must be a non-empty list of finite numbers, got {values!r}')
    return x


def _pair(a, b, what: str) -> tuple[np.ndarray, np.ndarray]:
    a, b = _sample(a, 'a'), _sample(b, 'b')
    if a.size < 2 or b.size < 2:
        raise ValueError(f'{what} needs at least 2 values per group, got {a.size} and {b.size}')
    return a, b


def _constant(x: np.ndarray) -> bool:
    """Every value the same (tested exactly: a variance can keep a rounding residue)."""
    return bool(np.ptp(x) == 0)


def _level(name: str, value: float) -> float:
    if not 0 < value < 1:
        raise ValueError(f'{name} must be between 0 and 1, got {value!r}')
    return value


def summarize(values, confidence: float = CONFIDENCE) -> Summary:
    """Mean, SD and the ``confidence`` interval of the mean (NaN spread for one value)."""
    x = _sample(values, 'values')
    mean = float(x[0]) if _constant(x) else float(x.mean())
    if x.size < 2:
        return Summary(1, mean, math.nan, math.nan, math.nan)
    sd = float(x.std(ddof=1)) if np.ptp(x) > 0 else 0.0    # no rounding residue
    half = float(stats.t.ppf(0.5 + confidence / 2, x.size - 1)) * sd / math.sqrt(x.size)
    return Summary(int(x.size), mean, sd, mean - half, mean + half)


def ttest(a, b, equal_var: bool = False) -> TTest:
    """Two-sided two-sample t-test of a against b: Welch's unless ``equal_var``."""
    a, b = _pair(a, b, 'a t-test')
    with warnings.catch_warnings():     # nearly constant groups: t is still defined
        warnings.simplefilter('ignore', RuntimeWarning)
        result = stats.ttest_ind(a, b, equal_var=equal_var)
    name = "Student's t-test" if equal_var else "Welch's t-test"
    t, df, p = float(result.statistic), float(result.df), float(result.pvalue)
    if _constant(a) and _constant(b):   # not a rounding residue's t: no test at all
        t = df = p = math.nan
    return TTest(name, t, df, p, summarize(a).mean, summarize(b).mean, int(a.size),
                 int(b.size))


def _welch(a: np.ndarray, b: np.ndarray, what: str) -> tuple[float, float, float]:
    """(a - b, its standard error, Welch-Satterthwaite df); refuses groups without spread."""
    va, vb = a.var(ddof=1) / a.size, b.var(ddof=1) / b.size
    if _constant(a) and _constant(b):
        raise ValueError(f'{what} is undefined: no spread within either group '
                         f'(all a = {a[0]:g}, all b = {b[0]:g})')
    df = (va + vb) ** 2 / (va * va / (a.size - 1) + vb * vb / (b.size - 1))
    return float(a.mean() - b.mean()), math.sqrt(va + vb), float(df)


def welch_interval(a, b, confidence: float = CONFIDENCE) -> Interval:
    """The difference of means a - b with its Welch ``confidence`` interval.

    Args:
        a, b: the two samples (>= 2 finite values each, not both constant).
        confidence: the interval's level, e.g. 0.95.

    Returns:
        An ``Interval``: difference +- t(df, (1 + confidence) / 2) * se.
    """
    a, b = _pair(a, b, 'a confidence interval')
    confidence = _level('confidence', confidence)
    diff, se, df = _welch(a, b, 'the confidence interval')
    half = float(stats.t.ppf(0.5 + confidence / 2, df)) * se
    return Interval(diff, diff - half, diff + half, confidence, se, df)


def hedges_g(a, b, confidence: float = CONFIDENCE) -> EffectSize:
    """Hedges' g of a against b with an exact confidence interval.

    Args:
        a, b: the two samples (>= 2 finite values each, some spread).
        confidence: the interval's level.

    Returns:
        An ``EffectSize``: d = (mean_a - mean_b) / pooled SD, g = J * d with
        J = Gamma(df/2) / (sqrt(df/2) Gamma((df-1)/2)), df = n_a + n_b - 2; the
        interval for delta inverts the noncentral t of Student's statistic (exact for
        normal data with equal variances).
    """
    a, b = _pair(a, b, "Hedges' g")
    confidence = _level('confidence', confidence)
    df = a.size + b.size - 2
    pooled = math.sqrt(((a.size - 1) * a.var(ddof=1) + (b.size - 1) * b.var(ddof=1)) / df)
    if _constant(a) and _constant(b):
        raise ValueError(f"Hedges' g is undefined: no spread within either group "
                         f'(all a = {a[0]:g}, all b = {b[0]:g})')
    d = float((a.mean() - b.mean()) / pooled)
    j = math.exp(special.gammaln(df / 2) - special.gammaln((df - 1) / 2)) / math.sqrt(df / 2)
    scale = math.sqrt(1 / a.size + 1 / b.size)
    t = d / scale
    tail = (1 - confidence) / 2
    ends = [_noncentrality(t, df, q) * scale for q in (1 - tail, tail)]
    return EffectSize(j * d, ends[0], ends[1], d)


def _noncentrality(t: float, df: int, q: float) -> float:
    """The noncentrality at which the observed t is the q-quantile (cdf falls as it grows)."""
    def gap(delta):
        return stats.nct.cdf(t, df, delta) - q
    step = 4.0 + abs(t)
    low, high = t - step, t + step
    while gap(low) < 0:
        low -= step
    while gap(high) > 0:
        high += step
    return float(optimize.brentq(gap, low, high, xtol=1e-10))


def rank_test(a, b) -> float:
    """Two-sided Mann-Whitney U p-value: a check on the t-test that a few collapsed
    trials (outliers far below the rest) cannot drive."""
    return mann_whitney(a, b).p


def mann_whitney(a, b) -> RankTest:
    """Two-sided Mann-Whitney U test with the common-language effect size.

    Args:
        a, b: the two samples (finite values).

    Returns:
        A ``RankTest``: U of a (pairs with a > b, ties counting 1/2), scipy's p
        (exact for small samples without ties), and U / (n_a n_b), the probability
        that a trial of a beats one of b.
    """
    a, b = _sample(a, 'a'), _sample(b, 'b')
    result = stats.mannwhitneyu(a, b, alternative='two-sided')
    u = float(result.statistic)
    return RankTest(u, float(result.pvalue), u / (a.size * b.size))


def tost(a, b, margin: float = PAPER_DIFFERENCE, alpha: float = ALPHA) -> Equivalence:
    """Two one-sided Welch tests that the difference a - b lies within (-margin, +margin).

    Args:
        a, b: the two samples (>= 2 finite values each, not both constant).
        margin: the equivalence margin (> 0), in the units of the data: the
            largest difference that would not matter, stated before looking.
        alpha: the level of each one-sided test.

    Returns:
        An ``Equivalence``: p = max(p_lower, p_upper); equivalent when p < alpha,
        which is the same as the 1 - 2 alpha Welch interval lying inside the margin.
    """
    a, b = _pair(a, b, 'an equivalence test')
    if not (isinstance(margin, (int, float)) and math.isfinite(margin) and margin > 0):
        raise ValueError(f'the equivalence margin must be a number > 0, got {margin!r}')
    alpha = _level('alpha', alpha)
    diff, se, df = _welch(a, b, 'the equivalence test')
    p_lower = float(stats.t.sf((diff + margin) / se, df))
    p_upper = float(stats.t.cdf((diff - margin) / se, df))
    half = float(stats.t.ppf(1 - alpha, df)) * se
    p = max(p_lower, p_upper)
    return Equivalence(float(margin), p, p_lower, p_upper, diff - half, diff + half,
                       max(abs(diff - half), abs(diff + half)), alpha, p < alpha)


def compare(a, b, margin: float = PAPER_DIFFERENCE, alpha: float = ALPHA,
            confidence: float = CONFIDENCE) -> Comparison:
    """All the estimates and tests of a against b (e.g. combination against independent).

    Args:
        a, b: the two samples, >= 2 finite values each (else ValueError).
        margin: the equivalence margin of the TOST (default: the paper's 0.032).
        alpha: the level of the Welch, rank and equivalence tests.
        confidence: the level of the difference's and g's intervals.

    Returns:
        A ``Comparison``.  If neither group varies, ``spread`` is False and every
        t-based number is NaN (the rank test and the means are still given).
    """
    a, b = _pair(a, b, 'a comparison')
    alpha, confidence = _level('alpha', alpha), _level('confidence', confidence)
    welch = ttest(a, b)
    rank = mann_whitney(a, b)
    sa, sb = summarize(a, confidence), summarize(b, confidence)
    if _constant(a) and _constant(b):
        nan = math.nan
        diff = sa.mean - sb.mean
        return Comparison(sa, sb, Interval(diff, nan, nan, confidence, 0.0, nan), welch,
                          EffectSize(nan, nan, nan, nan), rank,
                          Equivalence(float(margin), nan, nan, nan, nan, nan, nan, alpha,
                                      False), alpha, False)
    return Comparison(sa, sb, welch_interval(a, b, confidence), welch,
                      hedges_g(a, b, confidence), rank, tost(a, b, margin, alpha), alpha, True)


def describe(test: TTest) -> str:
    """'t(17.6) = 2.31, p = 0.033' in the usual reporting form."""
    if not math.isfinite(test.t):
        return 'no test (both groups constant)'
    return f't({test.df:.1f}) = {test.t:.2f}, {p_text(test.p)}'


def p_text(p: float) -> str:
    """'p = 0.033', 'p < 0.001', or 'p n/a' when undefined."""
    if not math.isfinite(p):
        return 'p n/a'
    return f'p = {p:.3f}' if p >= 0.001 else 'p < 0.001'
