"""Dump ``diagnosis.json`` of both ``bench_diagnose.py`` recordings (prints nothing else).

    python benchmark/same_answers.py OUTDIR [--skip-long] [--profile] [--sets]

For speed work that must not change an answer: dump before a change, dump after,
and ``cmp`` the files (``default.json``, ``long.json``).  ``--profile`` also writes
``<label>.prof`` (cProfile) beside each dump.  ``--sets`` also dumps seven small
recording sets that reach the paths the two stationary recordings do not (closed loop
with and without headings, dropouts, the world model's protocols, the emulated robot's
two protocols): each set's diagnosis, its target's comparisons with a few effects, and
every effect's fit, as ``set_<name>.json`` (floats written exactly).
"""
from __future__ import annotations

import argparse
import cProfile
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_diagnose  # noqa: E402  (sets the thread counts to 1 first)
from blind_gap import REPEATS, SAMPLES, STATIONARY  # noqa: E402

from khepera_noise_ros import effects as fx  # noqa: E402
from khepera_noise_ros.files import write_json  # noqa: E402
from khepera_noise_ros.gap import diagnose, select  # noqa: E402
from khepera_noise_ros.gap.target import Target  # noqa: E402
from khepera_noise_ros.reality.effects import EffectsConfig  # noqa: E402
from khepera_noise_ros.recording import Recording  # noqa: E402
from khepera_noise_ros.simconfig import SimConfig  # noqa: E402
from khepera_noise_ros.testing import emulated, protocols as pr  # noqa: E402

EIGHT = (0, 1, 2, 3, 4, 5, 6, 7)
# effects the sets' targets are compared with (no effect, a delay, a drift, a floor, a turn)
TRIALS = ((), (fx.SensorLatency(EIGHT, 1),), (fx.TemporalDrift((0, 1, 2), 0.01, 30.0, True),),
          (fx.SaturationQuantization((0, 1), dropout=0.005),), (fx.ActuatorTurnError(1.2, 0.1),))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('outdir', type=Path)
    p.add_argument('--skip-long', action='store_true')
    p.add_argument('--profile', action='store_true')
    p.add_argument('--sets', action='store_true')
    args = p.parse_args(argv)
    args.outdir.mkdir(parents=True, exist_ok=True)
    headings = sum(len(h) for h in STATIONARY.values())
    cases = [('default', SAMPLES)]
    if not args.skip_long:
        cases.append(('long', math.ceil(bench_diagnose.LONG_SAMPLES / (headings * REPEATS))))
    for label, per_heading in cases:
        rec = bench_diagnose.recording(per_heading)
        prof = cProfile.Profile() if args.profile else None
        c0 = time.process_time()
        if prof:
            prof.enable()
        _, result = bench_diagnose.timed(rec, 0)
        if prof:
            prof.disable()
            prof.dump_stats(str(args.outdir / f'{label}.prof'))
        cpu = time.process_time() - c0
        write_json(args.outdir / f'{label}.json', result.to_json())
        print(f'{label}: {cpu:.2f} s CPU', file=sys.stderr)
    if args.sets:
        for name, (recs, config) in sets().items():
            c0 = time.process_time()
            write_json(args.outdir / f'set_{name}.json', exact(answers(recs, config)))
            print(f'set {name}: {time.process_time() - c0:.2f} s CPU', file=sys.stderr)
    return 0


def sets() -> dict[str, tuple[list[Recording], SimConfig]]:
    """The small sets: recorded by the simulator with hidden effects, or the emulator."""
    world = [fx.LightResponse((4,), (0.0, 90.0), (5.0, 130.0), (500.0, 500.0),
                              (100.0, 480.0, 300.0, 490.0), 'model'),
             fx.SensorResponse((0, 1, 2), 0.6, 0.3, 0.5),
             fx.ActuatorResponse(3.0, 0.9, 0.2, (3.0, 9.0, 27.0), (0.5, 1.0, 1.1), 0.1, 0.5)]
    loop = [fx.SensorLatency(EIGHT, 1), fx.ActuatorTurnError(1.2, 0.1)]
    stat = [fx.IntensityDependentNoise((0, 1, 2, 3), 0.05, 1.0, 525.0, 0.0, 'dark', True),
            fx.TemporalDrift((4, 5), 0.01, 30.0, True)]
    robot = EffectsConfig.real_robot()
    return {
        'stationary': ([pr.recorded(pr.stationary_protocol(), stat, seed=1)], pr.CONFIG),
        'closed_loop': ([pr.recorded(pr.closed_loop_protocol(), loop, seed=2)], pr.CONFIG),
        'tracked': ([pr.tracked(pr.closed_loop_protocol(), loop, seed=3)], pr.CONFIG),
        'dropouts': ([pr.dropped(pr.recorded(pr.stationary_protocol(), stat, seed=4), (1, 6),
                                 0.004, 0.0),
                      pr.dropped(pr.recorded(pr.closed_loop_protocol(), loop, seed=5), (2,),
                                 0.004, 0.0)], pr.CONFIG),
        'world': ([pr.recorded(pr.sweep(), world, seed=7),
                   pr.recorded(pr.turn_calibration(), world, seed=8),
                   pr.recorded(pr.closed_loop_protocol(), world[1:] + loop[:1], seed=9)],
                  pr.CONFIG),
        'emulated': (emulated.recordings(robot, 3, 40, 20, emulated.evolved_genome(0)),
                     emulated.simulator(robot)),
    }


def answers(recs: list[Recording], config: SimConfig) -> dict[str, Any]:
    out: dict[str, Any] = {'diagnosis': diagnose.diagnose(
        recs, diagnose.Options(config=config, seed=0)).to_json()}
    target = Target(recs, config, 1)
    for j, effects in enumerate(TRIALS):
        try:
            c = target.compare(list(effects))
            out[f'compare_{j}'] = {'keys': [str(k) for k in c.keys], 'real': c.real,
                                   'sim': c.sim, 'z': c.z, 'objective':
                                   target.objective(list(effects))}
        except ValueError as exc:          # an effect this protocol cannot show
            out[f'compare_{j}'] = str(exc)
    c = target.compare()
    for name in fx.NAMES:
        cand = select.fit_one(name, target, c)
        out[f'fit_{name}'] = [None if cand.effect is None else cand.effect.to_dict(), cand.note]
    return out


def exact(x: Any) -> Any:
    """JSON with every float as its repr (a change in the last digit shows)."""
    if isinstance(x, (float, np.floating)):
        return repr(float(x))
    if isinstance(x, np.ndarray):
        return exact(x.tolist())
    if isinstance(x, dict):
        return {str(k): exact(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [exact(v) for v in x]
    return x


if __name__ == '__main__':
    sys.exit(main())
