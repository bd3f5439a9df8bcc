"""The paper's section 2 on a recording: how correlated the sensors' noise is, per condition.

For each condition and sensor pair it prints the Pearson correlation of the
fluctuations (each episode centred on its own mean) with a moving-block
bootstrap interval, which allows for drift and flicker, and the Fisher-z
interval, which assumes independent samples; then each sensor's mean, spread
and range.  It writes the numbers as JSON and CSV, time-series figures like
the paper's Figures 2-5, and a correlation-matrix heat map per condition.
"""
from __future__ import annotations

import argparse
import csv
import io
import re
from pathlib import Path

from .. import synchrony
from ..files import atomic_write_text, write_json
from ..recording import load
from ..synchrony import PAPER_FIGURES

HELP = "sensor-pair correlations per condition with intervals, and the paper's Figures 2-5"


def add_arguments(parser) -> None:
    parser.add_argument('recording', type=Path,
                        help='NAME, NAME.csv or NAME.yaml, or a rosbag2 directory')
    parser.add_argument('--pairs', nargs='+', type=_pair, metavar='A,B',
                        help='sensor pairs (none: 2,3, the paper\'s adjacent pair)')
    parser.add_argument('--out', type=Path,
                        help='output directory (none: NAME_synchrony beside the recording)')
    parser.add_argument('--by-heading', action='store_true',
                        help='analyse each start heading of a condition on its own')
    parser.add_argument('--figure', action='append', type=_figure, metavar='NAME=C1,C2',
                        help='conditions to draw together in one time-series figure '
                             '(none: the paper\'s bulb and ambient pairs, else all)')
    parser.add_argument('--confidence', type=float, default=0.95)
    parser.add_argument('--resamples', type=int, default=2000,
                        help='moving-block bootstrap resamples')
    parser.add_argument('--block', type=int, help='bootstrap block length in samples '
                        '(none: from the autocorrelation)')
    parser.add_argument('--seed', type=int, default=0, help='bootstrap seed')


def _pair(text: str) -> tuple[int, int]:
    try:
        a, b = (int(v) for v in text.split(','))
    except ValueError:
        raise argparse.ArgumentTypeError(f'a pair is two sensor numbers like 2,3; got '
                                         f'{text!r}') from None
    return a, b


def _figure(text: str) -> tuple[str, list[str]]:
    name, sep, conditions = text.partition('=')
    if not sep or not name or not conditions:
        raise argparse.ArgumentTypeError(f'a figure is NAME=CONDITION,CONDITION; got {text!r}')
    return name, conditions.split(',')


def run(args) -> int:
    rec = load(args.recording)
    results = synchrony.analyse(rec, args.pairs, args.confidence, args.resamples, args.block,
                                args.seed, args.by_heading)
    out = args.out or _default_out(args.recording)
    out.mkdir(parents=True, exist_ok=True)
    print(table(results, args.confidence))
    write_json(out / 'synchrony.json', {
        'format': 'khepera-noise-synchrony/1', 'recording': str(args.recording),
        'confidence': args.confidence, 'resamples': args.resamples,
        'conditions': [r.to_dict() for r in results]})
    atomic_write_text(out / 'synchrony.csv', to_csv(results))
    written = _figures(rec, results, args, out)
    print(f'-> {out}/synchrony.json, synchrony.csv and {len(written)} figures')
    return 0


def _default_out(recording: Path) -> Path:
    stem = recording.with_suffix('') if recording.suffix in ('.csv', '.yaml') else recording
    return stem.with_name(stem.name.removesuffix('_bag') + '_synchrony')


def _slug(text: str) -> str:
    return re.sub(r'[^A-Za-z0-9]+', '_', text).strip('_')


def _figures(rec, results, args, out: Path) -> list[Path]:
    written = []
    for result in results:
        path = out / f'synchrony_matrix_{_slug(result.condition)}.png'
        synchrony.plot_matrix(result, path)
        written.append(path)
    pairs = results[0].pairs if results else []
    for name, conditions in figure_groups(rec.conditions(), args.figure):
        for p in pairs:
            a, b = p.sensors
            path = out / f'synchrony_{_slug(name)}_s{a}_s{b}.png'
            title = synchrony.PAPER_TITLES.get(name, name)
            synchrony.plot_pair(rec, (a, b), conditions, path,
                                title=f'{title}: sensors s{a} and s{b}')
            written.append(path)
    return written


def figure_groups(conditions: list[str], requested=None) -> list[tuple[str, list[str]]]:
    """Which conditions share a time-series figure: as asked, the paper's pairs, or all."""
    if requested:
        return requested
    groups = [(name, list(c)) for name, c in PAPER_FIGURES.items() if set(c) <= set(conditions)]
    rest = [c for c in conditions if not any(c in g for _, g in groups)]
    return groups + ([('conditions' if not groups else 'other', rest)] if rest else [])


def table(results, confidence: float) -> str:
    """The numbers as aligned text: pairs first, then each sensor's level and spread."""
    pct = f'{100 * confidence:g}%'
    width = max([len(r.condition) for r in results] + [9])
    lines = [f'{"condition":<{width}}  {"n":>5} {"ep":>3}  pair    {"r":>6}  '
             f'{pct + " block bootstrap":<22}{pct + " Fisher-z":<18}block  paper r']
    for res in results:
        for p in res.pairs:
            paper = synchrony.paper_r(res.condition, p.sensors)
            lines.append(
                f'{res.condition:<{width}}  {res.samples:>5} {res.episodes:>3}  '
                f's{p.sensors[0]}-s{p.sensors[1]}  {p.r:>6.3f}  {_ci(p.bootstrap_ci):<22}'
                f'{_ci(p.fisher_ci):<18}{res.block_length:>5}  '
                f'{"" if paper is None else f"{paper:.2f}"}')
    lines += ['', f'{"condition":<{width}}  sensor    mean  noise std     min     max   range']
    for res in results:
        for c, s in res.sensors.items():
            lines.append(f'{res.condition:<{width}}  s{c:<5} {s.mean:>7.1f} {s.std:>10.2f} '
                         f'{s.min:>7.0f} {s.max:>7.0f} {s.range:>7.0f}')
    return '\n'.join(lines)


def _ci(ci) -> str:
    return f'[{ci[0]:.3f}, {ci[1]:.3f}]'


def to_csv(results) -> str:
    """One row per condition and pair."""
    buffer = io.StringIO()
    w = csv.writer(buffer, lineterminator='\n')
    w.writerow(['condition', 'samples', 'episodes', 'sensor_a', 'sensor_b', 'r',
                'bootstrap_low', 'bootstrap_high', 'fisher_low', 'fisher_high', 'block_length',
                'paper_r'])
    for res in results:
        for p in res.pairs:
            paper = synchrony.paper_r(res.condition, p.sensors)
            w.writerow([res.condition, res.samples, res.episodes, *p.sensors, p.r,
                        *p.bootstrap_ci, *p.fisher_ci, res.block_length,
                        '' if paper is None else paper])
    return buffer.getvalue()
