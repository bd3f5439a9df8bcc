"""The verdict rules on constructed samples whose means and SDs are exact."""
import math

import numpy as np
import pytest

from khepera_noise_ros.experiment import stats, verdict

# A fixed shape with mean exactly 0 and SD exactly 1, so a sample is mean + sd * shape.
_Z = np.array([-1.6, -1.1, -0.7, -0.4, -0.1, 0.1, 0.4, 0.7, 1.1, 1.6, -0.25, 0.25])


def sample(mean: float, sd: float, n: int = 10) -> np.ndarray:
    z = _Z[:n] if n <= len(_Z) else np.resize(_Z, n) + np.arange(n) * 1e-3
    z = (z - z.mean()) / z.std(ddof=1)
    return mean + sd * z


def judge(a, b, reference=None, margin=0.032, **kw) -> verdict.Verdict:
    return verdict.judge(stats.compare(a, b, margin=margin), reference=reference, **kw)


def test_clearly_better():
    a, b = sample(0.795, 0.02), sample(0.755, 0.02)
    c = stats.compare(a, b)
    v = verdict.judge(c, reference=0.032)
    assert v.kind == 'difference' and v.direction == 1 and v.rank_agrees
    low, high = c.interval.ci_low, c.interval.ci_high
    assert v.text == (f'combination better by 0.040 [{low:.3f}, {high:.3f}] '
                      f'({stats.p_text(c.welch.p)})')


def test_clearly_worse_gives_the_interval_of_the_stated_direction():
    a, b = sample(0.740, 0.02), sample(0.780, 0.02)
    c = stats.compare(a, b)
    v = verdict.judge(c)
    assert v.kind == 'difference' and v.direction == -1
    assert v.text.startswith(f'combination worse by 0.040 [{-c.interval.ci_high:.3f}, '
                             f'{-c.interval.ci_low:.3f}]')


def test_clearly_equivalent():
    v = judge(sample(0.781, 0.01, 12), sample(0.780, 0.01, 12))
    assert v.kind == 'equivalent'
    assert v.text.startswith('no difference larger than 0.032 (TOST p < 0.001; difference '
                             '+0.001 [')


def test_underpowered_when_the_interval_admits_the_paper_and_nothing():
    a, b = sample(0.775, 0.06), sample(0.765, 0.06)
    c = stats.compare(a, b)
    v = verdict.judge(c, reference=0.032)
    assert c.interval.ci_low < 0 < 0.032 < c.interval.ci_high
    assert v.kind == 'underpowered'
    assert v.text.startswith(f'underpowered: the CI [{c.interval.ci_low:.3f}, '
                             f"{c.interval.ci_high:.3f}] admits the paper's 0.032 and its "
                             f'absence (p = ')
    # without a paper number the margin is the difference of interest
    assert 'admits a difference of +0.032 and its absence' in verdict.judge(c).text


def test_inconclusive_when_the_interval_excludes_the_reference_but_not_the_other_side():
    a, b = sample(0.760, 0.03), sample(0.780, 0.03)
    c = stats.compare(a, b)
    assert c.interval.ci_low < -0.032 and c.interval.ci_high < 0.032 < 0.04
    assert c.welch.p > 0.05 and not c.equivalence.equivalent
    v = verdict.judge(c)
    assert v.kind == 'inconclusive'
    assert 'excludes a difference of +0.032 but reaches past ±0.032' in v.text


def test_a_significant_difference_inside_the_margin_is_trivial():
    a, b = sample(0.785, 0.003, 12), sample(0.780, 0.003, 12)
    v = judge(a, b)
    assert v.kind == 'trivial difference'
    assert v.text.startswith('combination better by 0.005 [')
    assert v.text.endswith('but by less than 0.032 (TOST p < 0.001)')


def test_no_spread_is_said_not_tested():
    v = judge([0.7, 0.7, 0.7], [0.6, 0.6])
    assert v.kind == 'no spread' and v.direction == 1
    assert v.text == 'no test: every trial within each model scored the same (0.700 vs 0.600)'


def test_a_collapsed_trial_makes_the_rank_test_disagree_and_the_text_says_so():
    a = sample(0.80, 0.01)
    b = np.append(sample(0.77, 0.01, 9), 0.05)      # one controller stopped working
    c = stats.compare(a, b)
    assert c.welch.p > 0.05 and c.rank.p < 0.05
    v = verdict.judge(c, reference=0.032)
    assert not v.rank_agrees
    assert v.text.endswith(f'; the rank test disagrees ({stats.p_text(c.rank.p)})')


def test_generations_read_sooner_and_later():
    a, b = sample(35.0, 3.0), sample(42.8, 3.0)
    v = judge(a, b, reference=-7.8, margin=7.8, words=('later', 'sooner'), digits=1)
    assert v.kind == 'difference' and v.text.startswith('combination sooner by 7.8 [')


@pytest.mark.parametrize('seed', range(40))
def test_the_rules_are_exhaustive_and_consistent(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 30))
    a = rng.normal(0.78 + rng.uniform(-0.05, 0.05), rng.uniform(0.005, 0.08), n)
    b = rng.normal(0.78, rng.uniform(0.005, 0.08), int(rng.integers(3, 30)))
    c = stats.compare(a, b)
    v = verdict.judge(c, reference=0.032)
    assert v.kind in verdict.KINDS
    low, high = c.interval.ci_low, c.interval.ci_high
    significant, eq = c.welch.p < 0.05, c.equivalence.equivalent
    expected = ('trivial difference' if significant and eq else 'difference' if significant
                else 'equivalent' if eq else 'underpowered' if low <= 0.032 <= high
                else 'inconclusive')
    assert v.kind == expected
    assert significant == (low > 0 or high < 0)            # the CI and p say the same
    assert v.direction == int(math.copysign(1, c.interval.difference))
