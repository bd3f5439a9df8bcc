"""Compound steps a small part explains, from ``blind_compound.py --out`` files (prints).

    python benchmark/part_steps.py BEFORE.json [AFTER.json]     (or the printed .txt output)

For each case of BEFORE: the rejected candidates whose step fails the overall paired
test (p >= STEP_ALPHA) while one part's own paired p passes (p < STEP_ALPHA, the step
removing MIN_LOCAL of that part before any effect or MIN_LEFT of what is left) and no
other part moves significantly (its own p between STEP_ALPHA and 1 - STEP_ALPHA).  With
AFTER (the same cases, diagnosed again): the steps counted by one part (``counted_by``
'part: ...') and every case whose chosen set changed.
"""
from __future__ import annotations

import ast
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from khepera_noise_ros.gap import compound  # noqa: E402

ALPHA = compound.STEP_ALPHA


def masked(entry: dict) -> str:
    """The part a rejected step explains while the others stay put, '' if none."""
    if entry.get('p_value', 0.0) < ALPHA or not entry.get('parts'):
        return ''
    parts = entry['parts']
    good = [p for p, d in parts.items() if d['p'] < ALPHA and
            (d['gain_before_any'] >= compound.MIN_LOCAL or d['gain_left'] >= compound.MIN_LEFT)]
    if len(good) != 1:
        return ''
    still = all(ALPHA <= d['p'] <= 1 - ALPHA for p, d in parts.items() if p != good[0])
    return good[0] if still else ''


def _cases(path: Path) -> dict:
    """Per case {'case', 'truth', 'answer', 'rejected', 'steps'}: from ``--out`` JSON, or
    (rejected entries only) from the printed output of a run cut short."""
    if path.suffix == '.json':
        return {r['case']: r for r in json.loads(path.read_text())['cases']}
    out, case = {}, None
    for line in path.read_text().splitlines():
        if line[:3] in ('ok ', 'XX ') and ' case ' in line:
            head = line.split('case', 1)[1].split()
            case = int(head[0])
            out[case] = {'case': case, 'truth': head[1].split('+'), 'rejected': [],
                         'answer': [] if head[3] == '-' else head[3].split('+'), 'steps': []}
        elif line.strip().startswith('rejected [') and case is not None:
            out[case]['rejected'] = ast.literal_eval(line.strip()[len('rejected '):])
    return out


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not 1 <= len(argv) <= 2:
        print('usage: part_steps.py BEFORE.json [AFTER.json]', file=sys.stderr)
        return 2
    before = _cases(Path(argv[0]))
    found = 0
    for k, r in sorted(before.items()):
        for e in r.get('rejected') or []:
            part = masked(e)
            if part:
                found += 1
                truth = 'true' if e['name'] in r['truth'] else 'FALSE'
                print(f"case {k:3d} {e['name']} ({truth}) masked, by {part}: overall p "
                      f"{e['p_value']:.3f}, added {e['added_reduction']:.4f}; {e['parts']}")
    print(f'{found} rejected steps explained by one part alone in {len(before)} cases')
    if len(argv) == 2:
        after = _cases(Path(argv[1]))
        for k, r in sorted(after.items()):
            by_part = [s for s in r['steps'] if str(s[3]).startswith('part')]
            old = before.get(k, {}).get('answer')
            if by_part or old != r['answer']:
                print(f"case {k:3d} truth {r['truth']}: {old} -> {r['answer']}; "
                      f"steps by a part {by_part}")
    return 0


if __name__ == '__main__':
    sys.exit(main())
