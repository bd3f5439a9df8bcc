"""Which of the emulated robot's effects its recordings can show (prints figures).

    python benchmark/emulated_set.py [--samples 60] [--episodes 30] [--seed 3]
                                     [--oracle-only] [--diagnose-only]
                                     [--rounding level|reading] [--alone NAME]
                                     [--refit NAME] [--robot v1|default]

The robot: ``v1`` (the default here), the robot of the emulator's first calibration, whose
six effects are all in the diagnosis's vocabulary; ``default``, today's robot (issue 27),
some of whose effects are not.  Recordings as test/gap/test_emulated_robot.py records
them (stationary, ``--samples`` per heading and condition; closed loop, ``--episodes``
episodes, headings unknown).

oracle     the robot's own effects, with their true parameters, put into the
           simulator: held-out discrepancy with all six, and with each one left out
           (p: paired bootstrap, that leaving it out does not raise the discrepancy).
           An effect whose absence raises nothing beyond the noise cannot be found.
diagnose   the diagnosis of the robot with one effect alone, and with every default
           effect but one: the single best effect and the compound chosen.
refit      (``--refit NAME``) the default robot: NAME fitted on the fitting part given
           none, then more and more of the robot's other effects with their true
           parameters (does the fitter find the true shape once the others are right?)
alone      (``--alone NAME``) the robot with only that effect and its sensor noise
           against the simulator with the effect's true parameters, statistic family
           by family: does the simulator's model reproduce the robot's process?

``--rounding`` is where the simulator rounds the reading ('level': the paper's,
the default; 'reading': noise added to the unrounded level, as the robot does).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

for var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(var, '1')
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402
from blind_gap import STATIONARY, record_closed_loop, record_stationary, robot  # noqa: E402

from khepera_noise_ros.core.noise import NoiseModel  # noqa: E402
from khepera_noise_ros.testing.protocols import GENOME  # noqa: E402
from khepera_noise_ros import effects as fx  # noqa: E402
from khepera_noise_ros.gap import diagnose, select, split  # noqa: E402
from khepera_noise_ros.gap.compare import paired_p  # noqa: E402
from khepera_noise_ros.simconfig import SimConfig  # noqa: E402
from khepera_noise_ros.gap.target import Target  # noqa: E402
from khepera_noise_ros.reality.effects import EffectsConfig  # noqa: E402

EIGHT = tuple(range(8))


def recordings(config, seed: int, samples: int, episodes: int) -> list:
    world = robot(config, seed)
    return [record_stationary(world, STATIONARY, samples=samples),
            record_closed_loop(world, np.array(GENOME), episodes=episodes, seed=seed)]


ROUNDING = ['level']        # the simulator's rounding (set by --rounding)


def simulator(config, rounding: str | None = None) -> SimConfig:
    return SimConfig(noise=NoiseModel.independent_only(config.sensor_noise,
                                                       rounding=rounding or ROUNDING[0]))


def true_effects(config) -> dict:
    """The robot's enabled effects in the diagnosis's vocabulary, true parameters, in the
    order the robot applies them (calibration, drift, flicker, group noise): the
    simulator applies effects in the order given, and the flicker's size depends on the
    calibrated level."""
    out = {}
    g = config.sensor_gain_offset
    if g.enabled:
        draws = np.random.default_rng([g.unit_seed]).standard_normal((2, 8))
        out['sensor_gain_offset'] = fx.SensorGainOffset(
            EIGHT, tuple(np.round(1 + g.strength * draws[0], 5)),
            tuple(np.round(g.offset_sd * draws[1], 4)))
    d = config.temporal_drift
    if d.enabled:
        out['temporal_drift'] = fx.TemporalDrift(tuple(d.location), d.strength,
                                                 d.time_constant, d.shared)
    f = config.intensity_dependent_noise
    if f.enabled:
        out['intensity_dependent_noise'] = fx.IntensityDependentNoise(
            tuple(f.location), f.strength, f.exponent, 525.0, 0.0, 'dark', True)
    c = config.correlated_noise
    if c.enabled:
        out['correlated_noise'] = fx.CorrelatedNoise(tuple(map(tuple, c.location)), c.strength)
    t = config.actuator_turn_error
    if t.enabled:
        out['actuator_turn_error'] = fx.ActuatorTurnError(t.scale, t.strength)
    s = config.sensor_latency
    if s.enabled:
        out['sensor_latency'] = fx.SensorLatency(tuple(s.location), s.strength)
    return out


def parts(recs, config, seed: int = 0, replicates: int = 100):
    """The fitting and held-out targets, made as ``diagnose`` makes them."""
    full = Target(recs, simulator(config), seed, 'auto', replicates=replicates)
    fit_part, test_part = split.split(recs, ())
    return [Target([r for _, r in part], simulator(config), seed + k, 'auto',
                   replicates=replicates,
                   block_lengths=[full.block_lengths[i] for i, _ in part])
            for k, part in ((1, fit_part), (2, test_part))]


def oracle(config, recs, sim_seeds: int = 1) -> None:
    """Per simulator seed (the simulated side's own noise), what leaving each true
    effect out adds to the held-out discrepancy of all six."""
    true = true_effects(config)
    rows: dict = {name: [] for name in true}
    for seed in range(sim_seeds):
        _, b = parts(recs, config, seed)
        before = b.compare()
        all_cmp = b.compare(list(true.values()))
        all_reps = b.replicate_discrepancies(all_cmp)
        d0, d_all = before.discrepancy, all_cmp.discrepancy
        print(f'  sim seed {seed}: held-out discrepancy none {d0:.1f}, all six true '
              f'{d_all:.1f} (shrink {1 - d_all / d0:.3f})')
        for name in true:
            rest = b.compare([e for n, e in true.items() if n != name])
            reps = b.replicate_discrepancies(rest)
            p = paired_p(reps, all_reps, rest.discrepancy, d_all)
            closed = (rest.part('closed_loop').discrepancy
                      - all_cmp.part('closed_loop').discrepancy)
            rows[name].append((rest.discrepancy - d_all, (rest.discrepancy - d_all) / d_all,
                               p, closed, (rest.discrepancy - d_all) / d0))
        if seed == 0:
            print('    what all six true leave, by statistic: ' + ', '.join(
                f'{f} {v:.0f}' for f, v in _by_family(all_cmp)[:5]))
    for name, r in rows.items():
        r = np.array(r)
        print(f'  without {name:27s} adds {r[:, 0].mean():+9.1f} (sd {r[:, 0].std():7.1f}) '
              f'= {r[:, 1].mean():+7.1%} of all-six\'s; p <= 0.05 in {np.sum(r[:, 2] <= 0.05)}'
              f'/{len(r)}; closed-loop part {r[:, 3].mean():+8.1f}; '
              f'{r[:, 4].mean():+.2%} of none\'s')


def effect_alone(config, name: str, samples: int, sim_seeds: int = 1,
                 seed: int = 3) -> None:
    """The robot with only ``name`` (and its sensor noise), stationary: the held-out
    discrepancy by statistic family without the effect and with its true parameters."""
    only = config.only(name)
    recs = recordings(only, seed, samples, 2)[:1]
    effect = true_effects(only)[name]
    if name == 'temporal_drift':
        _drift_states(only, effect, seed)
    for sim_seed in range(sim_seeds):
        _, b = parts(recs, only, sim_seed)
        c0, c1 = b.compare(), b.compare([effect])
        f0, f1 = dict(_by_family(c0)), dict(_by_family(c1))
        fams = sorted(set(f0) | set(f1), key=lambda f: -(f0.get(f, 0) + f1.get(f, 0)))
        print(f'  {name} alone, sim seed {sim_seed}: held-out none {c0.discrepancy:.0f}, true '
              f'{c1.discrepancy:.0f}; by family (none -> true): ' + ', '.join(
                  f'{f} {f0.get(f, 0):.0f} -> {f1.get(f, 0):.0f}' for f in fams[:8]))


def refit(config, name: str, samples: int, seed: int = 3) -> None:
    """``name`` fitted given the robot's other effects, true, one more at a time."""
    recs = recordings(config, seed, samples, 2)[:1]
    a, _ = parts(recs, config)
    true = true_effects(config)
    others = [n for n in ('sensor_gain_offset', 'sensor_latency', 'correlated_noise',
                          'temporal_drift', 'intensity_dependent_noise') if n != name]
    for k in range(len(others) + 1):
        given = a.with_given([true[n] for n in others[:k]])
        cand = select.fit_one(name, given, given.compare(replicates=40))
        print(f'  {name} given {others[:k] or "nothing"}: {cand.effect} ({cand.note})')
    print(f'  the robot\'s: {true[name]}')


def _drift_states(config, effect, seed: int, n: int = 20_000) -> None:
    """The robot's drift state and the simulator's over ``n`` samples: sd, lag-1."""
    world = robot(config, seed)
    drift = next(p for p in world._chain.chain if type(p).__name__ == 'Drift')
    states = []
    for _ in range(n):
        world.read(0)
        states.append(drift.state[0].copy())
    sim = effect.over_time(np.ones((n, 8, 1)), np.random.default_rng(0))[:, :, 0] - 1.0
    for label, x in (('robot', np.array(states)), ('simulator', sim)):
        lag1 = np.mean([np.corrcoef(x[1:, k], x[:-1, k])[0, 1] for k in range(8)])
        print(f'  drift state, {label}: sd {x.std(axis=0).mean():.5f}, lag-1 {lag1:.3f}')


def _by_family(c) -> list:
    """[(statistic family, its part of the discrepancy)], largest first."""
    out: dict = {}
    for k, z in zip(c.keys, c.z):
        out[k.family] = out.get(k.family, 0.0) + max(abs(z) - 2.0, 0.0) ** 2
    return sorted(out.items(), key=lambda t: -t[1])


def diagnosis(config, recs, label: str) -> None:
    t0 = time.process_time()
    r = diagnose.diagnose(recs, diagnose.Options(config=simulator(config), replicates=100))
    j = r.to_json()
    best = ', '.join(f'{e["name"]} {e["heldout_reduction"]:.2f}' for e in r.effects[:3])
    chosen = j['compound']['chosen'] if j['compound'] else []
    print(f'  {label}: gap significant {r.gap_significant}; top {r.top_effect}; best '
          f'{best}')
    if j.get('rounding'):
        print(f'    rounding: {j["rounding"]["note"]}')
    steps = [f'{c["name"]}{_where(c)} {c["cumulative_reduction"]:.3f}' for c in chosen]
    print('    compound: ' + ' -> '.join(steps)
          + (f'; rejected {j["compound"]["rejected"]}' if j['compound'] else '')
          + f'  [{time.process_time() - t0:.1f} s CPU]')


def _where(step: dict) -> str:
    """' (groups ...)' for shared noise, ' (s3, s4)' for effects on some sensors."""
    if 'groups' in step['parameters']:
        return f' (groups {step["parameters"]["groups"]})'
    sensors = step['sensors']
    return '' if not sensors or len(sensors) == 8 else \
        ' (' + ', '.join(f's{k}' for k in sensors) + ')'


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--samples', type=int, default=60)
    p.add_argument('--episodes', type=int, default=30)
    p.add_argument('--seed', type=int, default=3)
    p.add_argument('--sim-seeds', type=int, default=1)
    p.add_argument('--oracle-only', action='store_true')
    p.add_argument('--diagnose-only', action='store_true')
    p.add_argument('--rounding', choices=('level', 'reading'), default='level')
    p.add_argument('--refit', default=None, metavar='NAME',
                   help='only: NAME fitted given the robot\'s other true effects')
    p.add_argument('--alone', default=None, metavar='NAME',
                   help='only: the robot with this effect alone against its true parameters')
    p.add_argument('--effects', nargs='*', default=None,
                   help='effects to study alone and left out (default: every enabled one; none '
                        'given: none)')
    p.add_argument('--robot', choices=('v1', 'default'), default='v1')
    a = p.parse_args(argv)
    ROUNDING[0] = a.rounding
    robot_config = EffectsConfig.real_robot_v1() if a.robot == 'v1' else \
        EffectsConfig.real_robot()
    for flag in ('alone', 'refit'):
        if getattr(a, flag) not in (None,) + robot_config.enabled:
            print(f'--{flag} must be one of {list(robot_config.enabled)}, got '
                  f'{getattr(a, flag)!r}', file=sys.stderr)
            return 2
    if a.refit is not None:
        print(f'{a.samples} samples per cell, seed {a.seed}; simulator rounding {a.rounding}')
        refit(robot_config, a.refit, a.samples, a.seed)
        return 0
    if a.alone is not None:
        print(f'{a.samples} samples per cell, seed {a.seed}; simulator rounding {a.rounding}')
        effect_alone(robot_config, a.alone, a.samples, a.sim_seeds, a.seed)
        return 0
    print(f'recordings: {a.samples} samples per cell, {a.episodes} closed-loop episodes, '
          f'seed {a.seed}; simulator rounding {a.rounding}')
    recs = recordings(robot_config, a.seed, a.samples, a.episodes)
    if not a.diagnose_only:
        print('oracle (true parameters) on the default robot:')
        oracle(robot_config, recs, a.sim_seeds)
    if a.oracle_only:
        return 0
    diagnosis(robot_config, recs, 'default robot')
    for name in robot_config.enabled if a.effects is None else a.effects:
        alone = robot_config.only(name)
        diagnosis(alone, recordings(alone, a.seed, a.samples, a.episodes), f'{name} alone')
        without = robot_config.only(*[n for n in robot_config.enabled if n != name])
        diagnosis(without, recordings(without, a.seed, a.samples, a.episodes),
                  f'without {name}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
