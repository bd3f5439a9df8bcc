"""Two trees' blind-benchmark runs compared case by case (prints figures; not a test).

    python benchmark/paired_runs.py BEFORE.json AFTER.json [BEFORE.json AFTER.json ...]

Each pair is one benchmark run (``blind_outside.py``, ``blind_compound.py``, with
``--out``) of the same cases by two trees, or by one tree with two simulator seeds
(``--diagnosis-shift``).  Pairs are pooled: a change of the diagnosis is judged on many
fresh seeds together, not figure by figure (a seed's figures hold its simulator draws).

Per pair and pooled, over the compound cases' true effects: how many only BEFORE finds
and how many only AFTER finds (the exact two-sided sign test on these), the false effects
only one of them names (control cases too), and the recall difference with its 95%
interval (cases as clusters: a case's effects share its recording).  Single cases: how
many top-1 answers only one of them gets right.
"""
from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


@dataclass
class Paired:
    """Counts over the cases two runs share."""

    truth: int = 0
    only_before: int = 0
    only_after: int = 0
    false_before: int = 0
    false_after: int = 0
    top1_before: int = 0        # single cases right only before
    top1_after: int = 0
    clusters: list[tuple[int, int]] = field(default_factory=list)   # a compound case's (found
    # after - found before, true effects)

    def add(self, other: 'Paired') -> None:
        for name in ('truth', 'only_before', 'only_after', 'false_before', 'false_after',
                     'top1_before', 'top1_after'):
            setattr(self, name, getattr(self, name) + getattr(other, name))
        self.clusters += other.clusters


def cases(path: Path) -> dict[Any, dict[str, Any]]:
    """{case id: case} of a run's JSON; a one-line SystemExit if it is not one."""
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise SystemExit(f'{path}: not a benchmark run ({e})') from None
    rows = data.get('cases') if isinstance(data, dict) else None
    if not isinstance(rows, list):
        raise SystemExit(f'{path}: no "cases" list; pass the --out file of blind_outside.py '
                         'or blind_compound.py')
    return {c.get('id', c.get('case')): c for c in rows if isinstance(c, dict)}


def answer(case: dict[str, Any]) -> set[str]:
    return set(case.get('predicted', case.get('answer')) or [])


def compare(before: dict[Any, dict[str, Any]], after: dict[Any, dict[str, Any]]) -> Paired:
    out = Paired()
    for key in sorted(set(before) & set(after), key=str):
        b, a = before[key], after[key]
        if b.get('error') or a.get('error'):
            continue
        if b.get('kind') == 'single':
            out.top1_before += bool(b.get('top1')) and not a.get('top1')
            out.top1_after += bool(a.get('top1')) and not b.get('top1')
            continue
        truth, pb, pa = set(b['truth']), answer(b), answer(a)
        out.truth += len(truth)
        out.only_before += len((truth & pb) - pa)
        out.only_after += len((truth & pa) - pb)
        out.false_before += len((pb - truth) - pa)
        out.false_after += len((pa - truth) - pb)       # controls too: their truth is empty
        if truth:
            out.clusters.append((len(truth & pa) - len(truth & pb), len(truth)))
    return out


def sign_test(k: int, n: int) -> float:
    """Exact two-sided p of ``k`` of ``n`` discordant effects going one way."""
    if n == 0:
        return 1.0
    tail = sum(math.comb(n, i) for i in range(min(k, n - k) + 1)) / 2 ** n
    return min(1.0, 2 * tail)


def difference(clusters: list[tuple[int, int]]) -> tuple[float, float]:
    """(recall after - before, half-width of its 95% interval): a ratio estimate with
    cases as clusters."""
    total = sum(t for _, t in clusters)
    if total == 0 or len(clusters) < 2:
        return 0.0, math.nan
    d = sum(x for x, _ in clusters) / total
    m = len(clusters)
    var = sum((x - d * t) ** 2 for x, t in clusters) * m / (m - 1) / total ** 2
    return d, 1.96 * math.sqrt(var)


def line(label: str, p: Paired) -> str:
    d, half = difference(p.clusters)
    n = p.only_before + p.only_after
    return (f'{label}: {p.truth} true effects in {len(p.clusters)} compound cases; found only '
            f'before {p.only_before}, only after {p.only_after} (sign test p = '
            f'{sign_test(p.only_before, n):.3f}); recall after - before {100 * d:+.1f} points '
            f'(95% interval {100 * (d - half):+.1f} to {100 * (d + half):+.1f}); false effects '
            f'only before {p.false_before}, only after {p.false_after}; single top-1 right '
            f'only before {p.top1_before}, only after {p.top1_after}')


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('runs', type=Path, nargs='+', metavar='BEFORE AFTER')
    args = p.parse_args()
    if len(args.runs) % 2:
        p.error(f'{len(args.runs)} files: pass them in pairs, BEFORE then AFTER')
    pooled = Paired()
    for before, after in zip(args.runs[::2], args.runs[1::2]):
        b, a = cases(before), cases(after)
        if set(b) != set(a) or any(sorted(b[k].get('truth') or []) !=
                                   sorted(a[k].get('truth') or []) for k in b):
            p.error(f'{before} and {after} hold different cases: run the same benchmark, '
                    'seed and --cases with both trees')
        one = compare(b, a)
        print(line(f'{before.name} -> {after.name}', one))
        pooled.add(one)
    if len(args.runs) > 2:
        print(line('pooled', pooled))


if __name__ == '__main__':
    main()
