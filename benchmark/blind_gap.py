"""Blind benchmark of the sim-to-real gap diagnosis (prints figures; not a test).

    python benchmark/blind_gap.py [--cases 40] [--seed 0] [--samples 60] [--transfer N]
                                   [--out FILE.json]
    python benchmark/blind_gap.py --record EFFECTS_YAML --to DIR [--seed 0]

Each case draws one effect of the vocabulary (or none) at a random location and
strength and sets it in the emulated robot (``reality.EmulatedWorld``), which
then records a stationary and a closed-loop recording, as an experimenter
would: the stationary one at fixed headings in five lighting conditions, the
closed-loop one running an evolved controller on the light-centring task, with
the heading unknown (a real robot does not know it).  The diagnosis
(``gap.diagnose``) gets only the two recordings and the simulator's
configuration; the case's settings stay in this script, which at the end
compares them with the answers: a confusion matrix of the top effect, how often
the location was right when the effect was, and the held-out shrink.

The simulator's configuration is the paper's independent model at the
emulator's own sensor-noise level (2%), so ``none`` means no gap.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault('OMP_NUM_THREADS', '1')

import numpy as np  # noqa: E402

from khepera_noise_ros.core import evolution  # noqa: E402
from khepera_noise_ros.core.evaluation import episode_fitness  # noqa: E402
from khepera_noise_ros.core.noise import NoiseModel  # noqa: E402
from khepera_noise_ros.core.task import Task  # noqa: E402
from khepera_noise_ros.experiment import transfer  # noqa: E402
from khepera_noise_ros.gap import diagnose  # noqa: E402
from khepera_noise_ros.effects import VOCABULARY  # noqa: E402
from khepera_noise_ros.reality.khepera_robot import InProcessRobots, KheperaRobots  # noqa: E402
from khepera_noise_ros.simconfig import SimConfig  # noqa: E402
from khepera_noise_ros.reality import effects as emu  # noqa: E402
from khepera_noise_ros.recording import Recording  # noqa: E402
# the emulated robot and its recording protocols, shared with the tests
from khepera_noise_ros.testing.emulated import (  # noqa: E402,F401
    CLOSED_LOOP_EPISODES, REPEATS, SAMPLES, SENSOR_NOISE, SETTLE, STATIONARY, SWEEP,
    evolved_genome, record_closed_loop, record_stationary, robot)

RING = (0, 1, 2, 3, 4, 5, 6, 7)          # sensors in order around the body: adjacent pairs


def _arc(rng, low: int, high: int) -> tuple:
    """Adjacent sensors around the body, ``low``..``high`` of them."""
    size = int(rng.integers(low, high + 1))
    start = int(rng.integers(0, 8))
    return tuple(sorted(RING[(start + i) % 8] for i in range(size)))


def draw_case(rng, name: str | None = None) -> tuple[str, emu.EffectsConfig, dict]:
    """(effect name, emulator configuration, truth: location and settings); ``name``
    chooses the effect (else it is drawn)."""
    if name is None:
        name = VOCABULARY[int(rng.integers(0, len(VOCABULARY)))]
    base = emu.EffectsConfig.none(SENSOR_NOISE)
    if name == 'none':
        return name, base, {'location': None}
    if name == 'correlated_noise':
        first = _arc(rng, 2, 4)
        groups = [first]
        if rng.random() < 0.5:
            rest = [s for s in RING if s not in first]
            start = rest.index(min(rest, key=lambda s: (s - max(first)) % 8))
            size = int(rng.integers(2, 4))
            second = tuple(sorted(rest[start:start + size]))
            if len(second) >= 2 and all((b - a) % 8 == 1 or (a, b) == (0, 7) for a, b in
                                        zip(second, second[1:])):
                groups.append(second)
        settings = {'strength': float(rng.uniform(0.01, 0.03)), 'location': tuple(groups)}
        truth = {'location': sorted(map(list, groups))}
    elif name == 'intensity_dependent_noise':
        location = _arc(rng, 3, 8)
        settings = {'strength': float(rng.uniform(0.02, 0.06)),
                    'exponent': float(rng.uniform(1.0, 3.0)), 'location': location}
        truth = {'location': list(location)}
    elif name == 'sensor_gain_offset':
        location = tuple(sorted(rng.choice(8, size=int(rng.integers(1, 4)), replace=False)))
        gains, offsets = [1.0] * 8, [0.0] * 8
        for s in location:
            gains[s] = 1.0 + float(rng.choice([-1, 1]) * rng.uniform(0.05, 0.2))
            offsets[s] = float(rng.uniform(-10, 10))
        settings = {'gains': tuple(gains), 'offsets': tuple(offsets),
                    'location': tuple(int(s) for s in location)}
        truth = {'location': [int(s) for s in location]}
    elif name == 'temporal_drift':
        location = RING if rng.random() < 0.5 else _arc(rng, 2, 6)
        settings = {'strength': float(rng.uniform(0.006, 0.02)),
                    'time_constant': float(rng.uniform(10, 80)),
                    'shared': bool(rng.random() < 0.5), 'location': tuple(location)}
        truth = {'location': list(location)}
    elif name == 'actuator_turn_error':
        scale = rng.uniform(0.6, 0.85) if rng.random() < 0.5 else rng.uniform(1.15, 1.4)
        settings = {'scale': float(scale), 'strength': float(rng.uniform(0.0, 0.3))}
        truth = {'location': None}
    elif name == 'sensor_latency':
        location = RING if rng.random() < 0.5 else _arc(rng, 2, 6)
        settings = {'strength': int(rng.integers(1, 3)), 'location': tuple(location)}
        truth = {'location': list(location)}
    else:
        location = _arc(rng, 1, 4)
        kind = rng.choice(['high', 'low', 'step', 'high+step'])
        settings = {'location': location, 'strength': 1.0}
        if 'high' in kind:
            settings['high'] = float(rng.uniform(380, 480))
        if kind == 'low':
            settings['low'] = float(rng.uniform(60, 120))
        if 'step' in kind:
            settings['strength'] = float(rng.choice([3, 4, 5, 8]))
        truth = {'location': list(location), 'kind': str(kind)}
    truth['settings'] = {k: list(v) if isinstance(v, tuple) else v for k, v in settings.items()}
    return name, base.only(name, **{name: settings}), truth


def effective_location(config: emu.EffectsConfig, seed: int, recorded: Recording,
                       samples: int = SAMPLES) -> list:
    """The sensors whose stationary readings the effect changed: the same robot, seed and
    protocol without the effect (the emulator's draws do not depend on which effects are
    on) differs from the recording exactly where the effect acted."""
    plain = record_stationary(robot(emu.EffectsConfig.none(SENSOR_NOISE), seed),
                              samples=samples)
    return [int(s) for s in np.flatnonzero((plain.readings != recorded.readings).any(axis=0))]


def located(name: str, truth: dict, answer: dict | None, key: str = 'effective') -> bool:
    """Did the diagnosis name the right sensors (or groups)?  ``key`` chooses the truth:
    'effective' (sensors whose data changed) or 'location' (the emulator's setting)."""
    if truth['location'] is None:
        return True
    if answer is None:
        return False
    if name == 'correlated_noise':
        groups = answer['parameters'].get('groups', [])
        return sorted(map(sorted, groups)) == sorted(map(sorted, truth['location']))
    return sorted(answer['sensors']) == sorted(truth[key])


# --- reality for the transfer experiment ----------------------------------------------

def reality(config: emu.EffectsConfig, seed: int, condition: str = 'task'):
    """(genomes, seeds) -> fitness on emulated robots of ``config``: the robots the
    benchmark recorded from, one per genome."""
    from khepera_noise_ros.reality.world import CONDITIONS as conditions
    world = conditions[condition].world()

    def evaluate(genomes, seeds):
        bodies = robot(config, seed, len(seeds))
        env = KheperaRobots(InProcessRobots(bodies), world, Task())
        try:
            return episode_fitness(env, genomes, seeds)
        finally:
            env.close()
    return evaluate


# --- the run ------------------------------------------------------------------------

TRANSFER_ANSWERS = ('actuator_turn_error', 'sensor_latency')   # effects that act in the loop
TRANSFER_EA = evolution.EAConfig(population=15, generations=20)


def run_case(k: int, rng, genome, options, transfer_trials: int,
             samples: int = SAMPLES) -> dict:
    name, config, truth = draw_case(rng)
    seed = int(rng.integers(0, 2 ** 31))
    world = robot(config, seed)
    t0 = time.perf_counter()
    recordings = [record_stationary(world, samples=samples),
                  record_closed_loop(world, genome, seed=seed)]
    record_s = time.perf_counter() - t0
    if truth['location'] is not None:
        truth['effective'] = effective_location(config, seed, recordings[0], samples)
    t0 = time.perf_counter()
    result = diagnose.diagnose(recordings, dataclasses.replace(options, seed=k))
    answer = next((e for e in result.effects if e['name'] == result.top_effect), None)
    diagnose_s = time.perf_counter() - t0
    if transfer_trials and result.top_effect in TRANSFER_ANSWERS:
        from khepera_noise_ros.reality.world import CONDITIONS as conditions
        result.transfer = transfer.run(options.config, conditions['task'].world(),
                                       [result.fitted], reality(config, seed + 1),
                                       transfer_trials, TRANSFER_EA, seed=k)
    return {'case': k, 'truth': name, 'truth_detail': truth, 'answer': result.top_effect,
            'correct': result.top_effect == name,
            'located': result.top_effect == name and located(name, truth, answer),
            'located_setting': result.top_effect == name and located(name, truth, answer,
                                                                     'location'),
            'answer_sensors': answer['sensors'] if answer else [],
            'answer_parameters': answer['parameters'] if answer else {},
            'shrink': answer['heldout_reduction'] if answer else None,
            'gap_significant': result.gap_significant, 'transfer': result.transfer,
            'compound': [c['name'] for c in
                         (result.to_json().get('compound') or {}).get('chosen', [])],
            'record_s': record_s, 'diagnose_s': diagnose_s}


def confusion(rows: list[dict]) -> str:
    names = list(VOCABULARY)
    short = {n: ''.join(w[0] for w in n.split('_')) for n in names}
    lines = ['truth \\ answer'.ljust(28) + ''.join(short[n].rjust(5) for n in names)]
    for t in names:
        counts = [sum(1 for r in rows if r['truth'] == t and r['answer'] == a) for a in names]
        lines.append(t.ljust(28) + ''.join(str(c).rjust(5) for c in counts))
    lines.append('columns: ' + ', '.join(f'{short[n]} = {n}' for n in names))
    return '\n'.join(lines)


def summary(rows: list[dict], seconds: float) -> dict:
    correct = [r for r in rows if r['correct']]
    effect_rows = [r for r in rows if r['truth'] != 'none']
    shrink_all = [r['shrink'] if r['correct'] else 0.0 for r in effect_rows]
    shrink_correct = [r['shrink'] for r in effect_rows if r['correct']]
    transfers = [r for r in rows if r['transfer']]
    return {
        'cases': len(rows), 'top1': len(correct) / len(rows),
        'located': sum(r['located'] for r in correct) / max(1, len(correct)),
        'located_setting': sum(r['located_setting'] for r in correct) / max(1, len(correct)),
        'median_shrink_effect_cases': float(np.median(shrink_all)) if shrink_all else None,
        'median_shrink_correct': float(np.median(shrink_correct)) if shrink_correct else None,
        # the compound set of a one-effect case should be that effect alone
        'compound_exact': float(np.mean([r['compound'] == [r['truth']] for r in effect_rows]))
        if effect_rows else None,
        'transfer_cases': len(transfers),
        'transfer_gap_before': [r['transfer']['fitness_gap_before'] for r in transfers],
        'transfer_gap_after': [r['transfer']['fitness_gap_after'] for r in transfers],
        'transfer_p': [r['transfer']['gap_p'] for r in transfers],
        'seconds': seconds, 'seconds_per_case': seconds / len(rows),
    }


def record_only(effects: Path, out: Path, seed: int) -> int:
    """Record the benchmark's two protocols from an emulator, for the commands to read."""
    from khepera_noise_ros.recording import write_csv
    world = robot(emu.EffectsConfig.load(effects), seed)
    genome = evolved_genome(seed)
    for name, rec in (('stationary', record_stationary(world)),
                      ('closed_loop', record_closed_loop(world, genome, seed=seed))):
        for path in write_csv(rec, out / name):
            print(f'wrote {path}')
    params = out / 'simulator.yaml'
    params.write_text('simulator:\n  ros__parameters:\n    noise_model: independent\n'
                      f'    independent_level: {SENSOR_NOISE}\n')
    print(f'wrote {params}')
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--cases', type=int, default=40)
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--transfer', type=int, default=0, metavar='N',
                   help='re-run the transfer experiment in the first N cases answered '
                        + ' or '.join(TRANSFER_ANSWERS))
    p.add_argument('--transfer-trials', type=int, default=5)
    p.add_argument('--out', type=Path, default=None, help='write the per-case results here')
    p.add_argument('--record', type=Path, metavar='EFFECTS_YAML',
                   help='instead: record the protocol from the emulator of this effects '
                        'file into --to (stationary and closed_loop CSV + YAML)')
    p.add_argument('--to', type=Path, default=Path('results/recordings'))
    p.add_argument('--samples', type=int, default=SAMPLES,
                   help='stationary readings per heading (693: an hour at 10 Hz, as '
                        'bench_diagnose.py\'s long recording)')
    args = p.parse_args(argv)
    if args.record:
        return record_only(args.record, args.to, args.seed)
    started = time.perf_counter()
    rng = np.random.default_rng(args.seed)
    genome = evolved_genome(args.seed)
    config = SimConfig(noise=NoiseModel.independent_only(SENSOR_NOISE))
    options = diagnose.Options(config=config)
    rows = []
    for k in range(args.cases):
        transfer_trials = args.transfer_trials if sum(bool(r['transfer']) for r in rows) \
            < args.transfer else 0
        row = run_case(k, rng, genome, options, transfer_trials, args.samples)
        rows.append(row)
        mark = 'ok ' if row['correct'] else 'XX '
        where = '' if row['located'] or not row['correct'] else (
            f" wrong location {row['answer_sensors']} (changed: "
            f"{row['truth_detail'].get('effective')}, set: {row['truth_detail']['location']})")
        shrink = '' if row['shrink'] is None else f" shrink {row['shrink']:.2f}"
        extra = [n for n in row['compound'] if n != row['truth']]
        added = f" + compound {extra}" if extra else ''
        print(f"{mark}case {k:3d} {row['truth']:26s} -> {row['answer']:26s}{shrink}{where}"
              f"{added} ({row['diagnose_s']:.1f} s)", flush=True)
    seconds = time.perf_counter() - started
    s = summary(rows, seconds)
    print()
    print(confusion(rows))
    print()
    print(f"cases {s['cases']}, top-1 {s['top1']:.0%}, location right in {s['located']:.0%} "
          f"of correct answers ({s['located_setting']:.0%} against the emulator's location "
          f"setting), median held-out shrink {s['median_shrink_effect_cases']:.2f} "
          f"over effect cases ({s['median_shrink_correct']:.2f} over correct ones), "
          f"compound set exactly the one effect in {s['compound_exact']:.0%} of effect cases, "
          f"{seconds:.0f} s ({s['seconds_per_case']:.1f} s per case)")
    for r in rows:
        if r['transfer']:
            t = r['transfer']
            print(f"transfer case {r['case']} ({r['truth']} -> {r['answer']}): fitness gap "
                  f"{t['fitness_gap_before']:.3f} -> {t['fitness_gap_after']:.3f} "
                  f"(Welch p = {t['gap_p'] if t['gap_p'] is None else round(t['gap_p'], 3)}), "
                  f"real fitness {t['real_fitness_before']:.3f} -> "
                  f"{t['real_fitness_after']:.3f}, {t['trials']} trials")
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({'summary': s, 'cases': rows}, indent=1,
                                       default=float))
    return 0


if __name__ == '__main__':
    sys.exit(main())
