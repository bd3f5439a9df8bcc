"""Scoring a diagnosis.json against the hidden truth (rules in docs/blind-benchmark.md).

- single-effect case: right when ``top_effect`` is the injected name.
- location: among right answers whose effect lives on sensors, right when the
  named sensors overlap the injected ones with Jaccard >= 0.5 (no sensors
  named counts as all eight).
- compound case: the predicted set is the diagnosis's selected set: a list
  under ``compound``/``selected``, else ``combined``'s effect names, else,
  when ``combined`` is there but empty (null), the top effect alone; a file
  with none of these keys gets every effect with held-out reduction >=
  SHRINK_MIN (and p <= P_MAX where a p-value is given).  Precision and
  recall of that set against the injected names.
- shrink: single cases, the top effect's held-out reduction; compound cases,
  the selected set's cumulative reduction (``combined``'s when that is all
  there is, else the best single effect's).
"""
from __future__ import annotations

import math

SHRINK_MIN = 0.2
P_MAX = 0.05
JACCARD_MIN = 0.5
ALL = list(range(8))


def _names(entries) -> list[str] | None:
    if isinstance(entries, list):
        out = [e.get('name') if isinstance(e, dict) else e for e in entries]
        return [n for n in out if isinstance(n, str)]
    return None


def selected(diag: dict) -> tuple[list[str], str, float | None]:
    """(effect names, where they came from, the set's held-out reduction)."""
    for key in ('compound', 'selected'):
        value = diag.get(key)
        if isinstance(value, dict):
            for inner in ('effects', 'chosen', 'steps', 'selected'):
                names = _names(value.get(inner))
                if names is not None:
                    return [n for n in names if n != 'none'], key, _shrink_of(value)
        names = _names(value)
        if names is not None:
            shrink = None
            if value and isinstance(value[-1], dict):
                shrink = _first(value[-1], ('cumulative_reduction', 'cumulative',
                                            'heldout_reduction'))
            return [n for n in names if n != 'none'], key, shrink
    combined = diag.get('combined')
    if isinstance(combined, dict):
        for inner in ('effects', 'names', 'chosen'):
            names = _names(combined.get(inner))
            if names is not None:
                return [n for n in names if n != 'none'], 'combined', _shrink_of(combined)
    if 'combined' in diag and not combined:
        top = diag.get('top_effect')
        entry = next((e for e in diag.get('effects', []) if e.get('name') == top), {})
        return ([top] if top and top != 'none' else []), 'top_effect', \
            (entry.get('heldout_reduction') or 0.0) if top != 'none' else 0.0
    names = [e['name'] for e in diag.get('effects', [])
             if e.get('name') != 'none' and (e.get('heldout_reduction') or 0) >= SHRINK_MIN
             and (e.get('p_value') is None or e['p_value'] <= P_MAX)]
    best = max([e.get('heldout_reduction') or 0.0 for e in diag.get('effects', [])] + [0.0])
    return names, 'threshold', best


def _first(d: dict, keys):
    for k in keys:
        v = d.get(k)
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            return float(v)
    return None


def _shrink_of(d: dict):
    return _first(d, ('cumulative_reduction', 'heldout_reduction', 'cumulative', 'reduction'))


def jaccard(a, b) -> float:
    a, b = set(a), set(b)
    return len(a & b) / len(a | b) if a | b else 1.0


def score_case(case: dict, diag: dict | None) -> dict:
    """Per-case verdict: the fields the summary aggregates."""
    truth = [e.name for e in case['effects']]
    out = {'truth': truth, 'top_effect': None, 'top1': False, 'location': None,
           'predicted': [], 'predicted_from': None, 'precision': None, 'recall': None,
           'shrink': None}
    if diag is None:
        if case['kind'] == 'compound':
            out.update(precision=0.0, recall=0.0)
        return out
    top = diag.get('top_effect')
    out['top_effect'] = top
    effects = {e['name']: e for e in diag.get('effects', [])}
    names, source, set_shrink = selected(diag)
    out['predicted'], out['predicted_from'] = names, source
    if case['kind'] == 'single':
        injected = case['effects'][0]
        out['top1'] = top == injected.name
        top_entry = effects.get(top, {})
        out['shrink'] = top_entry.get('heldout_reduction', 0.0) if top != 'none' else 0.0
        out['injected_shrink'] = effects.get(injected.name, {}).get('heldout_reduction')
        if out['top1'] and injected.sensors:
            named = top_entry.get('sensors') or ALL
            out['named_sensors'] = named
            out['location'] = jaccard(named, injected.sensors) >= JACCARD_MIN
    elif case['kind'] == 'compound':
        hit = set(names) & set(truth)
        out['precision'] = len(hit) / len(set(names)) if names else 0.0
        out['recall'] = len(hit) / len(set(truth))
        out['shrink'] = set_shrink
    else:
        out['top1'] = top == 'none'
    if out['shrink'] is not None and not math.isfinite(out['shrink']):
        out['shrink'] = None
    return out
