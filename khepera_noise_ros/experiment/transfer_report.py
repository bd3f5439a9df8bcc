"""The transfer block as a report section and as lines for the terminal."""
from __future__ import annotations

from .transfer import DIAGNOSED, ROBOT, STOCK

WHERE = {STOCK: 'the stock simulator (as configured)',
         DIAGNOSED: 'the diagnosed simulator (the fitted effects)',
         'independent': "the stock simulator with the paper's independent noise (5%)",
         'combination': "the stock simulator with the paper's combination noise (3% + 2%)",
         ROBOT: 'the robot itself, seeded from the stock bests (the ceiling)'}


def _ci(s: dict | None) -> str:
    if s is None:
        return '-'
    return f"{s['mean']:.3f} [{s['ci_low']:.3f}, {s['ci_high']:.3f}]"


def _versus(v: dict | None) -> str:
    if v is None:
        return '-'
    return f"{v['difference']:+.3f} [{v['ci_low']:+.3f}, {v['ci_high']:+.3f}]"


def share_text(t: dict) -> str:
    """'share recovered 0.42 [0.10, 0.80]', or why there is none."""
    if t.get('share_recovered') is None:
        return t.get('share_note') or 'no robot-trained arm (--transfer-ceiling)'
    ci = t.get('share_recovered_interval')
    bounds = f' [{ci[0]:.2f}, {ci[1]:.2f}]' if ci else ' (interval unbounded)'
    return f"share recovered {t['share_recovered']:.2f}{bounds}"


def markdown(t: dict) -> str:
    """The section of report.md: the arms' table, the share recovered, the recommendation."""
    lines = ['## Transfer: controllers from each simulator, tested on the robot', '',
             f"{t['trials']} trials per arm, each best chosen by re-test and tested on "
             f"{t['test_episodes']} episodes on the robot (trial i of every arm on the same "
             f"episodes); EA {t['ea']['generations']} generations of {t['ea']['population']}. "
             'Means with 95% t intervals; the difference from the stock arm is Welch\'s.', '',
             '| arm | evolved in | sim fitness | real fitness [95% CI] | real - stock [95% CI] '
             '| verdict |', '| --- | --- | --- | --- | --- | --- |']
    for name, a in t['arms'].items():
        if not a.get('tested'):
            lines.append(f'| {name} | {WHERE.get(name, name)} | not tested | | | |')
            continue
        v = a.get('versus_stock')
        same = f" (same simulator as {a['same_as']})" if a.get('same_as') else ''
        lines.append(f"| {name} | {WHERE.get(name, name)}{same} | {_ci(a['sim'])} | "
                     f"{_ci(a['real'])} | {_versus(v)} | {v['verdict'] if v else '-'} |")
    lines += ['', f'- Robot-trained: {share_text(t)}.']
    if t.get('verdict_text'):
        lines.append(f"- Diagnosed simulator: {t['verdict_text']}.")
    lines.append(f"- {recommendation_line(t)}")
    if t.get('status') != 'complete':
        lines.append(f"- **Stopped**: {t.get('error')} ({t.get('done')}).")
    return '\n'.join(lines) + '\n'


def recommendation_line(t: dict) -> str:
    """One line: whether fitted_params.yaml is the recommendation, and why."""
    if t.get('recommended') is None:
        return f"fitted_params.yaml is not judged by the transfer: {t['recommendation']}"
    if t['recommended']:
        return f"fitted_params.yaml is recommended: {t['recommendation']}"
    return (f"Not recommended, so written as fitted_params.rejected.yaml: "
            f"{t['recommendation']}")


def lines(t: dict) -> list[str]:
    """Per-arm lines and the verdict, for the terminal."""
    out = []
    for name, a in t['arms'].items():
        if a.get('tested'):
            v = a.get('versus_stock')
            out.append(f"  transfer {name:14s} real {_ci(a['real'])}  sim {_ci(a['sim'])}"
                       + (f"  {v['verdict']}" if v else ''))
    out.append(f'  transfer: {share_text(t)}')
    out.append(f'  {recommendation_line(t)}')
    return out
