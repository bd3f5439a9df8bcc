"""Power of a two-sided Welch t-test, before a run and after it.

How large a difference can ``n`` trials per model find, how likely they are
to find the paper's, and how many trials that would take.  The noncentral t
distribution of scipy; docs/statistics.md gives the formulas and why.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from scipy import optimize, stats

ALPHA = 0.05
TARGET_POWER = 0.80
# Section 4.4: at 5%, step 5, "0.795 versus 0.763 with p < 0.05" (Table 1: 0.7952, 0.7627).
PAPER_DIFFERENCE = 0.032
# Spreads shown when none has been measured yet: from a paper-like spread (the paper's
# p < 0.05 for 0.032 with ten trials needs SD <= 0.034) to one with collapsed trials.
ASSUMED_SDS = (0.02, 0.03, 0.05, 0.08)
MAX_TRIALS = 10_000_000


@dataclass(frozen=True)
class Plan:
    """The power of one design: ``n`` trials per model at a per-trial SD ``sd``."""

    sd: float                 # per-trial standard deviation, both models
    n: int                    # trials per model
    alpha: float              # two-sided
    target: float             # the power asked of a design, e.g. 0.80
    difference: float         # the difference of interest, e.g. the paper's 0.032
    mdd: float                # minimum difference detected with probability ``target``
    power: float              # probability of detecting ``difference`` with ``n``
    trials_needed: int        # trials per model to detect ``difference`` with ``target``
    source: str               # where sd comes from: 'assumed', 'measured: ...'


def _check(name: str, value, low: float, high: float = math.inf, open_low=True) -> float:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and \
        math.isfinite(value) and (value > low if open_low else value >= low) and value < high
    if not ok:
        bound = f'> {low:g}' if open_low else f'>= {low:g}'
        limit = f' and < {high:g}' if math.isfinite(high) else ''
        raise ValueError(f'{name} must be a finite number {bound}{limit}, got {value!r}')
    return float(value)


def _trials(name: str, n) -> int:
    if isinstance(n, bool) or not isinstance(n, int) or n < 2:
        raise ValueError(f'{name} must be an integer >= 2, got {n!r}')
    return n


def _design(sd, n, alpha, sd_b, n_b) -> tuple[float, float, float]:
    """(standard error of the difference, Welch-Satterthwaite df, critical t)."""
    sd = _check('sd', sd, 0.0)
    sd_b = sd if sd_b is None else _check('sd_b', sd_b, 0.0)
    n = _trials('n', n)
    n_b = n if n_b is None else _trials('n_b', n_b)
    alpha = _check('alpha', alpha, 0.0, 1.0)
    va, vb = sd * sd / n, sd_b * sd_b / n_b
    df = (va + vb) ** 2 / (va * va / (n - 1) + vb * vb / (n_b - 1))
    return math.sqrt(va + vb), df, float(stats.t.ppf(1 - alpha / 2, df))


def power(difference: float, sd: float, n: int, alpha: float = ALPHA, *,
          sd_b: float | None = None, n_b: int | None = None) -> float:
    """Probability that a two-sided Welch t-test at ``alpha`` finds a true difference.

    Args:
        difference: the true difference of the two means (its sign does not matter).
        sd: the per-trial standard deviation (of both models unless ``sd_b`` is given).
        n: trials per model (of the first model if ``n_b`` is given), >= 2.
        alpha: the two-sided significance level.
        sd_b, n_b: the second model's SD and trials, if they differ.

    Returns:
        The power in [alpha, 1].  With equal SDs and trials this is exactly the power
        of Student's test (Welch's df is then 2n - 2); otherwise the usual
        approximation with Welch-Satterthwaite df at the true SDs.
    """
    difference = _check('difference', difference, -math.inf)
    se, df, critical = _design(sd, n, alpha, sd_b, n_b)
    shift = difference / se
    upper, lower = stats.nct.sf(critical, df, shift), stats.nct.cdf(-critical, df, shift)
    # far in a tail scipy's noncentral t can return NaN (seen at 50 trials, shift 9); the
    # normal approximation is then accurate to far below what the power is quoted to
    if not math.isfinite(upper):
        upper = stats.norm.sf(critical - shift)
    if not math.isfinite(lower):
        lower = stats.norm.cdf(-critical - shift)
    return float(upper + lower)


def minimum_detectable_difference(sd: float, n: int, alpha: float = ALPHA,
                                  target: float = TARGET_POWER, *, sd_b: float | None = None,
                                  n_b: int | None = None) -> float:
    """The smallest true difference a Welch test at ``alpha`` finds with probability ``target``.

    Args:
        sd: the per-trial standard deviation (both models unless ``sd_b``).
        n: trials per model (the first model's if ``n_b``).
        alpha: two-sided significance level.
        target: the power asked for, in (alpha, 1).
        sd_b, n_b: the second model's SD and trials, if they differ.

    Returns:
        The minimum detectable difference, in the units of ``sd``.
    """
    target = _check('target', target, alpha, 1.0)
    se, _, _ = _design(sd, n, alpha, sd_b, n_b)

    def gap(d):
        return power(d, sd, n, alpha, sd_b=sd_b, n_b=n_b) - target
    high = se
    while gap(high) < 0:            # power grows with d: bracket, then solve
        high *= 2
    return float(optimize.brentq(gap, 0.0, high, xtol=1e-12 * high, rtol=1e-12))


def trials_needed(difference: float, sd: float, alpha: float = ALPHA,
                  target: float = TARGET_POWER, *, sd_b: float | None = None) -> int:
    """Trials per model for a Welch test at ``alpha`` to find ``difference`` with ``target`` power.

    Args:
        difference: the true difference to detect, non-zero.
        sd: the per-trial standard deviation (both models unless ``sd_b``).
        alpha: two-sided significance level.
        target: the power asked for, in (alpha, 1).
        sd_b: the second model's SD, if it differs.

    Returns:
        The smallest n >= 2 (the same for both models) whose power reaches ``target``.
    """
    difference = abs(_check('difference', difference, -math.inf))
    if difference == 0:
        raise ValueError('difference must be non-zero: no number of trials detects 0')
    target = _check('target', target, alpha, 1.0)

    def enough(n: int) -> bool:
        return power(difference, sd, n, alpha, sd_b=sd_b, n_b=n) >= target
    low, high = 2, 4
    if enough(low):
        return low
    while not enough(high):          # power grows with n: bracket, then bisect
        low, high = high, high * 2
        if high > MAX_TRIALS:
            raise ValueError(f'difference {difference:g} at sd {sd:g} needs more than '
                             f'{MAX_TRIALS} trials per model')
    while high - low > 1:
        mid = (low + high) // 2
        low, high = (low, mid) if enough(mid) else (mid, high)
    return high


def largest_sd(difference: float, n: int, alpha: float = ALPHA,
               target: float = TARGET_POWER) -> float:
    """The largest per-trial SD at which ``n`` trials per model find ``difference``
    with ``target`` power (the MDD scales with the SD, so one solve suffices).

    Args:
        difference: the difference to detect, non-zero.
        n: trials per model.
        alpha, target: as for ``minimum_detectable_difference``.

    Returns:
        The SD, in the units of ``difference``.
    """
    difference = abs(_check('difference', difference, -math.inf))
    if difference == 0:
        raise ValueError('difference must be non-zero')
    return difference / minimum_detectable_difference(1.0, n, alpha, target)


def significant_below(difference: float, n: int, alpha: float = ALPHA) -> float:
    """The largest pooled SD at which an observed ``difference`` between two groups of ``n``
    is significant at ``alpha`` (two-sided; Welch's df are at most 2n - 2, so this bounds it).

    Args:
        difference: the observed difference of means.
        n: trials per group.
        alpha: two-sided significance level.

    Returns:
        |difference| / (t(1 - alpha/2, 2n - 2) * sqrt(2/n)).
    """
    difference = abs(_check('difference', difference, -math.inf))
    n, alpha = _trials('n', n), _check('alpha', alpha, 0.0, 1.0)
    return difference / (float(stats.t.ppf(1 - alpha / 2, 2 * n - 2)) * math.sqrt(2 / n))


def plan(sd: float, n: int, difference: float = PAPER_DIFFERENCE, alpha: float = ALPHA,
         target: float = TARGET_POWER, source: str = 'assumed') -> Plan:
    """The power analysis of one design (equal SDs and trials in both models).

    Args:
        sd: per-trial SD, measured or assumed.
        n: configured trials per model.
        difference: the difference of interest (default: the paper's 0.032 at step 5).
        alpha: two-sided significance level; target: the power asked for.
        source: a few words on where ``sd`` comes from, shown in the tables.

    Returns:
        A ``Plan`` with the minimum detectable difference at ``n``, the power for
        ``difference`` at ``n`` and the trials ``difference`` needs.
    """
    return Plan(float(sd), n, alpha, target, float(difference),
                minimum_detectable_difference(sd, n, alpha, target),
                power(difference, sd, n, alpha), trials_needed(difference, sd, alpha, target),
                source)


def pooled_sd(sd_a: float, sd_b: float) -> float:
    """The root mean square of two SDs: the common SD of two equal-sized groups."""
    return math.sqrt((sd_a * sd_a + sd_b * sd_b) / 2)


def plan_table(plans, what: str = 'difference') -> str:
    """A Markdown table of ``plans``: SD, n, MDD, power and trials needed for each.

    Args:
        plans: ``Plan`` objects (all for the same alpha, target and difference is clearest).
        what: the name of the difference in the header, e.g. "the paper's 0.032".

    Returns:
        The table as text, one row per plan.
    """
    head = ('SD per trial', 'Source', 'Trials per model', 'Detectable at '
            f'{plans[0].target:.0%} power', f'Power for {what}', f'Trials needed for {what}')
    rows = [f'| {p.sd:.3f} | {p.source} | {p.n} | {p.mdd:.3f} | {p.power:.0%} | '
            f'{p.trials_needed} |' for p in plans]
    return '\n'.join([f"| {' | '.join(head)} |", '|' + ' --- |' * len(head), *rows])
