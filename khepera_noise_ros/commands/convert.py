"""Convert a public multi-sensor log into a recording (CSV + YAML manifest).

room-occupancy: the UCI Room Occupancy Estimation CSV; --channels picks up to
eight of its columns (default the four light and four temperature sensors),
conditions are occupancy_0..3 from Room_Occupancy_Count.  intel-lab: the Intel
Berkeley Research Lab data.txt; --motes picks up to eight motes and --quantity
one reading of theirs, conditions are day and night from the log's clock.
Each quantity is mapped onto 0..525 with 0 at its most (brightest, warmest);
the map is written in the manifest under converted_from.
"""
from __future__ import annotations

from pathlib import Path

from ..convert import FORMATS, INTEL_QUANTITIES, OCCUPANCY_CHANNELS, convert
from ..recording import write_csv

HELP = 'convert a public multi-sensor log (room-occupancy, intel-lab) into a recording'


def add_arguments(parser) -> None:
    parser.add_argument('format', choices=FORMATS)
    parser.add_argument('input', type=Path, help='the published file')
    parser.add_argument('out', type=Path, help='NAME: writes NAME.csv and NAME.yaml')
    parser.add_argument('--channels', nargs='+', default=list(OCCUPANCY_CHANNELS),
                        metavar='COLUMN', help='room-occupancy: columns for s0, s1, ...')
    parser.add_argument('--motes', nargs='+', type=int, default=list(range(1, 9)),
                        metavar='ID', help='intel-lab: motes for s0, s1, ...')
    parser.add_argument('--quantity', choices=INTEL_QUANTITIES, default='light',
                        help='intel-lab: which reading of the motes')
    parser.add_argument('--episode-length', type=int, default=60,
                        help='longest episode, samples (longer runs are cut)')
    parser.add_argument('--min-length', type=int, default=10,
                        help='shorter runs are dropped')
    parser.add_argument('--range', nargs=3, action='append', default=[],
                        metavar=('QUANTITY', 'LOW', 'HIGH'),
                        help='scale QUANTITY from LOW..HIGH instead of the data\'s own range')


def run(args) -> int:
    ranges = {}
    for quantity, low, high in args.range:
        try:
            ranges[quantity] = (float(low), float(high))
        except ValueError:
            raise ValueError(f'--range {quantity} needs two numbers, got {low!r} {high!r}') \
                from None
    rec = convert(args.format, args.input, channels=args.channels, motes=args.motes,
                  quantity=args.quantity, episode_length=args.episode_length,
                  min_length=args.min_length, ranges=ranges)
    csv_path, yaml_path = write_csv(rec, args.out)
    info = rec.manifest['converted_from']
    labels = {c: int((rec.condition == c).sum()) for c in rec.conditions()}
    print(f'{len(rec)} samples in {len(set(rec.episode.tolist()))} episodes '
          f'({info["dropped_samples"]} dropped), period {rec.manifest["sample_period_s"]:g} s, '
          f'conditions {labels}')
    for name, ch in info['channels'].items():
        print(f"  {name}: {ch['column']} ({ch['quantity']}, {ch['low']:g}..{ch['high']:g} "
              f"{ch['unit']})")
    print(f'-> {csv_path}, {yaml_path}')
    return 0
