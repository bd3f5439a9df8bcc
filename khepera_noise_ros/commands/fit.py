"""Fit the combination noise model to a stationary recording (the paper's "observe the
robot to build the model"), and write a params YAML for the simulator node.

Dependence groups come from clustering the sensors' residual correlations,
dependent and independent levels from their covariances (calibrated by
simulating the model, since getnoise truncates), the distribution from the
closer of uniform and normal, and, where the data show that the noise grows
with the light level faster than the model's proportional scaling, an
intensity_dependent_noise effect checked on held-out data.  Recordings of any
number of light channels are accepted (the manifest's channels_used marks the
ones read); groups beyond the Khepera's 8 channels are reported but cannot be
loaded by the simulator.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

from ..core.khepera import SENSORS
from ..core.noise import format_groups
from ..files import write_json
from .. import simconfig
from ..experiment import noisefit
from ..recording import load

HELP = 'fit the combination noise model to a stationary recording; write simulator params'


def add_arguments(parser) -> None:
    parser.add_argument('recording', type=Path, metavar='RECORDING',
                        help='NAME (NAME.csv + NAME.yaml) or a rosbag2 directory')
    parser.add_argument('--params', type=Path, metavar='YAML',
                        help='a params file to start from (its world and task are kept)')
    parser.add_argument('--out', type=Path, default=Path('results/fitted_noise.yaml'),
                        help='the params YAML to write (a .json summary goes beside it)')
    parser.add_argument('--no-level-dependence', action='store_true',
                        help='fit the plain combination model only')
    parser.add_argument('--seed', type=int, default=0)


def run(args) -> int:
    base = simconfig.load(args.params)
    rec = load(args.recording)
    result = noisefit.fit(rec, base, args.seed, level_dependence=not args.no_level_dependence)
    print(f'dependence groups: {result.groups or "none (independent model)"}')
    print(f'dependent level d = {result.dependent:.4f}, independent level i = '
          f'{result.independent:.4f}, distribution {result.distribution}')
    if result.by_condition:
        print(f"per condition, the combination model with groups "
              f"{result.by_condition[0]['groups'] or 'none'}:")
    for row in result.by_condition:
        corr = row['within_group_correlation']
        print(f"  {row['condition']:18s} mean level {row['mean_level']:6.1f}  "
              f"d {row['dependent']:.4f}  i {row['independent']:.4f}  within-group "
              f"correlation {'n/a' if corr is None else f'{corr:.2f}'}")
    for e in result.effects:
        print(f'  plus {e.name}: {e}')
    for note in result.notes:
        print(f'  {note}')
    summary = args.out.with_suffix('.json')
    write_json(summary, _summary(result, args.recording))
    try:
        config = dataclasses.replace(base, noise=result.noise_model(), effects=result.effects)
    except ValueError as exc:
        print(f'not written as simulator params: {exc}')
        print(f'wrote {summary}')
        return 0
    if rec.channels != SENSORS:
        print(f'note: the simulator node models the Khepera\'s {SENSORS} sensors; these '
              f'parameters describe channels 0..{rec.channels - 1} of the recording')
    keys = simconfig.NOISE_KEYS + (('effects',) if result.effects else ())
    simconfig.write(config, args.out, keys=keys,
                    header=f'khepera-noise fit {args.recording}\nload with: --ros-args '
                           f'--params-file {args.out.name}')
    print(f'wrote {args.out} and {summary}')
    return 0


def _summary(result: noisefit.NoiseFit, source: Path) -> dict:
    return {'format': 'khepera-noise-fit/1', 'recording': str(source),
            'dependence_groups': result.groups,
            'dependence_groups_text': format_groups(result.groups),
            'dependent_level': result.dependent, 'independent_level': result.independent,
            'distribution': result.distribution, 'by_condition': result.by_condition,
            'effects': [e.to_dict() for e in result.effects], 'notes': result.notes}
