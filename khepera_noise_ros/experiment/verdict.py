"""Verdicts phrased from the interval and the equivalence test, not from p alone.

The rules, in order (alpha and the margin are the comparison's own):

1. ``no spread``: neither group varies, so nothing can be tested.
2. Welch p < alpha, and the TOST shows the difference is within the margin:
   ``trivial difference`` ("combination better by 0.004 [0.001, 0.007] (p = 0.010),
   but by less than 0.032 (TOST p = 0.001)").
3. Welch p < alpha: ``difference`` ("combination better by 0.031 [0.010, 0.052]
   (p = 0.004)"); the interval is of the stated direction's size.
4. TOST p < alpha: ``equivalent`` ("no difference larger than 0.032 (TOST p = 0.010)").
5. The 95% interval holds both 0 and the reference difference (the paper's, else
   the margin): ``underpowered`` ("underpowered: the CI [-0.040, 0.050] admits the
   paper's 0.032 and its absence").
6. Otherwise ``inconclusive``: the interval excludes the reference but reaches
   past the margin on the other side, so neither a difference nor its absence
   is shown.

Whenever the rank test's decision at alpha differs from Welch's, the text says so.
"""
from __future__ import annotations

from dataclasses import dataclass

from .stats import Comparison, p_text

KINDS = ('difference', 'trivial difference', 'equivalent', 'underpowered', 'inconclusive',
         'no spread')


@dataclass(frozen=True)
class Verdict:
    kind: str             # one of KINDS
    direction: int        # sign of a - b: +1, -1 or 0
    text: str             # the sentence for the report
    rank_agrees: bool     # the rank test reaches the same decision at alpha as Welch's


def judge(comparison: Comparison, reference: float | None = None,
          names: tuple[str, str] = ('combination', 'independent'),
          words: tuple[str, str] = ('better', 'worse'), digits: int = 3,
          reference_name: str | None = None) -> Verdict:
    """Phrase what ``comparison`` (a against b) can and cannot say.

    Args:
        comparison: the result of ``stats.compare(a, b, margin, alpha)``.
        reference: the difference a - b of interest, signed (e.g. the paper's +0.032
            at step 5, or -7.8 generations); default: +margin.
        names: what a and b are called; only the first appears ("combination better").
        words: how a - b > 0 and a - b < 0 read for a ("better"/"worse", or
            "later"/"sooner" for generations).
        digits: decimals of the numbers in the text.
        reference_name: how the reference is called; default "the paper's X" when a
            reference is given, else "a difference of +margin".

    Returns:
        A ``Verdict`` by the rules of this module's docstring.
    """
    c = comparison
    eq, diff = c.equivalence, c.interval.difference
    direction = (diff > 0) - (diff < 0)
    if not c.spread:
        return Verdict('no spread', direction,
                       f'no test: every trial within each model scored the same '
                       f'({c.a.mean:.{digits}f} vs {c.b.mean:.{digits}f})', True)
    if reference_name is None:
        reference_name = (f'a difference of {eq.margin:+.{digits}f}' if reference is None
                          else f"the paper's {reference:.{digits}f}")
    if reference is None:
        reference = eq.margin

    def f(x: float) -> str:
        return f'{x:.{digits}f}'

    low, high = c.interval.ci_low, c.interval.ci_high
    p, tost_p = p_text(c.welch.p), 'TOST ' + p_text(eq.p)
    significant = c.welch.p < c.alpha
    if significant:
        word = words[0] if direction > 0 else words[1]
        ends = (low, high) if direction > 0 else (-high, -low)
        text = f'{names[0]} {word} by {f(abs(diff))} [{f(ends[0])}, {f(ends[1])}] ({p})'
        if eq.equivalent:
            kind = 'trivial difference'
            text += f', but by less than {f(eq.margin)} ({tost_p})'
        else:
            kind = 'difference'
    elif eq.equivalent:
        kind = 'equivalent'
        text = (f'no difference larger than {f(eq.margin)} ({tost_p}; difference '
                f'{diff:+.{digits}f} [{f(low)}, {f(high)}], {p})')
    elif low <= reference <= high:
        kind = 'underpowered'
        text = (f'underpowered: the CI [{f(low)}, {f(high)}] admits {reference_name} and '
                f'its absence ({p}, {tost_p} at ±{f(eq.margin)})')
    else:
        kind = 'inconclusive'
        text = (f'inconclusive: the CI [{f(low)}, {f(high)}] excludes {reference_name} but '
                f'reaches past ±{f(eq.margin)} ({p}, {tost_p})')
    rank_agrees = (c.rank.p < c.alpha) == significant
    if not rank_agrees:
        text += f'; the rank test disagrees ({p_text(c.rank.p)})'
    return Verdict(kind, direction, text, rank_agrees)
