"""Record a robot node's light readings as CSV + YAML and as a rosbag2 (MCAP) bag.

The recorder is the controller of one robot node on the lockstep topics: it
starts each episode, answers every reading, and keeps each (episode, step)
exactly once.  A resent reading is answered again but kept once; steps that
never come are reported and listed in the manifest as lost_steps.  The
stationary protocol is the paper's section 2: one episode of N samples per
condition and heading, always answered with power 0.  The closed-loop protocol
lets a genome's network drive the robot for N episodes of the task.  The robot
node is started in this process (--robot) or is already running (--attach).
"""
from __future__ import annotations

import sys
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

import numpy as np
import yaml

from ..core import network
from ..recording import (FORMAT, SOURCES, Recording, bag_path, concatenate, write_csv)

HELP = 'record light readings from a robot node (stationary or closed loop) to CSV and MCAP'
CONDITION_KEYS = ('lamp_distance_mm', 'ambient')
Policy = Callable[[np.ndarray], tuple[int, int]]


# -- conditions ---------------------------------------------------------------------------

def named_conditions() -> dict[str, dict]:
    """The emulator's lighting conditions (reality/world.py) as robot-node parameters."""
    from ..reality.world import CONDITIONS
    return {name: {'lamp_distance_mm': float(c.lamp_distance_mm), 'ambient': float(c.ambient)}
            for name, c in CONDITIONS.items()}


def parse_conditions(text: str) -> dict[str, dict]:
    """``paper``, a comma list of condition names, or a YAML file {label: {param: value}}."""
    known = named_conditions()
    if text.endswith(('.yaml', '.yml')):
        data = yaml.safe_load(Path(text).read_text())
        if not isinstance(data, dict) or not all(isinstance(v, dict) for v in data.values()):
            raise ValueError(f'{text}: expected a mapping of condition labels to parameters')
        for label, params in data.items():
            unknown = set(params) - set(CONDITION_KEYS)
            if unknown:
                raise ValueError(f'{text}: condition {label!r} sets {sorted(unknown)}; a '
                                 f'condition sets {list(CONDITION_KEYS)}')
        return {str(k): dict(v) for k, v in data.items()}
    from ..reality.world import SECTION2
    names = SECTION2 if text == 'paper' else tuple(n for n in text.split(',') if n)
    unknown = [n for n in names if n not in known]
    if unknown or not names:
        raise ValueError(f'unknown condition(s) {unknown or text!r}; known: paper, '
                         f'{", ".join(sorted(known))}, or a YAML file')
    return {n: known[n] for n in names}


# -- policies ----------------------------------------------------------------------------

def hold_still(readings: np.ndarray) -> tuple[int, int]:
    """The stationary protocol's answer: no turn."""
    return 1, 0


def genome_policy(genome: np.ndarray) -> Policy:
    weights = network.unpack(genome)

    def policy(readings: np.ndarray) -> tuple[int, int]:
        direction, power = network.act(weights, readings.reshape(1, -1))
        return int(direction[0]), int(power[0])
    return policy


# -- in-process robot nodes ---------------------------------------------------------------

ROBOTS = ('simulator', 'emulator', 'emulator-world')


def start_robot(kind: str, context, args) -> tuple[object, Callable[[], None]]:
    """(robot node, close) for ``--robot``, in this process.

    ``emulator`` is the emulator on a pseudo-terminal behind the hardware bridge:
    the whole serial path a real Khepera takes.  ``emulator-world`` drives the
    emulator's world directly, without the serial link.
    """
    if kind == 'simulator':
        from ..nodes.simulator import Simulator
        return Simulator(context=context, parameter_overrides=_simulator_overrides(args)), \
            lambda: None
    from ..reality.effects import EffectsConfig
    from ..reality.world import EmulatedWorld
    world = EmulatedWorld(EffectsConfig.load(args.effects) if args.effects else None,
                          seed=args.seed)
    if kind == 'emulator-world':
        from ..nodes.world_node import WorldNode
        return WorldNode(world, context=context), lambda: None
    from rclpy.parameter import Parameter

    from ..nodes.hardware_bridge import HardwareBridge
    from ..reality.emulator import Emulator
    emulator = Emulator(world, seed=args.seed).start()
    try:
        bridge = HardwareBridge(context=context, parameter_overrides=[
            Parameter('ports', value=emulator.ports[:1]), Parameter('autostart', value=True)])
    except BaseException:
        emulator.stop()
        raise
    return bridge, emulator.stop


def _simulator_overrides(args) -> list:
    from rclpy.parameter import Parameter
    return [Parameter('noise_model', value=args.model),
            Parameter('dependent_level', value=float(args.dependent)),
            Parameter('independent_level', value=float(args.independent)),
            Parameter('dependence_groups', value=args.groups),
            Parameter('distribution', value=args.distribution)]


# -- the command --------------------------------------------------------------------------

def add_arguments(parser) -> None:
    from . import _options
    parser.add_argument('out', type=Path, help='NAME: writes NAME.csv, NAME.yaml and NAME_bag/')
    parser.add_argument('--protocol', choices=('stationary', 'closed-loop', 'sweep', 'turns'),
                        default='stationary',
                        help='sweep: stationary placements round the circle (the light '
                             'response); turns: the turn calibration (docs/identification.md)')
    robot = parser.add_mutually_exclusive_group()
    robot.add_argument('--robot', choices=ROBOTS, default='simulator',
                       help='robot node to start in-process: the simulator, the emulator '
                            'behind the hardware bridge, or the emulator\'s world directly')
    robot.add_argument('--attach', metavar='NODE',
                       help='record an already running robot node, e.g. /khepera/bridge')
    parser.add_argument('--source', choices=SOURCES,
                        help='what the attached node is (required with --attach)')
    s = parser.add_argument_group('stationary protocol (section 2)')
    s.add_argument('--conditions', default='paper',
                   help="'paper' (bulb_1ft, bulb_2ft, room_fluorescent, room_dark), a comma "
                        "list of condition names, or a YAML file "
                        "{label: {lamp_distance_mm: .., ambient: ..}}")
    s.add_argument('--headings', type=float, nargs='+', default=[0.0], metavar='DEG',
                   help='lamp bearings to record at (0 = straight ahead, CCW positive)')
    s.add_argument('--samples', type=int, default=None,
                   help='samples per condition and heading (default 60; sweep: 10)')
    s.add_argument('--sweep-step', type=float, default=10.0, metavar='DEG',
                   help='sweep: degrees between headings where the lamp is on')
    s.add_argument('--sweep-passes', type=int, default=2, metavar='N',
                   help='sweep: times round the circle, each the other way')
    s.add_argument('--period', type=float, default=1.0,
                   help='sample period, s (the paper: 1 s); see --pace')
    s.add_argument('--ask', action='store_true',
                   help='wait for Enter before each condition (to set up a real room)')
    c = parser.add_argument_group('closed-loop protocol')
    c.add_argument('--genome', type=Path, help='controller genome (JSON list or evolve result)')
    c.add_argument('--episodes', type=int, default=10)
    c.add_argument('--steps', type=int, default=60, help='steps per episode')
    c.add_argument('--condition', default='task',
                   help='condition name for closed-loop and turn-calibration runs')
    c.add_argument('--turn-rest', type=int, default=10, metavar='N',
                   help='turns: readings at rest before each turn (at least 10)')
    c.add_argument('--turn-repeats', type=int, default=3, metavar='N',
                   help='turns: placements per power (each with 2 turns each way)')
    parser.add_argument('--pace', action='store_true',
                        help='answer readings no faster than one per period (for hardware)')
    parser.add_argument('--seed', type=int, default=0, help='episode seeds are seed + episode')
    parser.add_argument('--timeout', type=float, default=5.0,
                        help='seconds without news before the rest of an episode counts as lost')
    parser.add_argument('--effects', type=Path,
                        help='emulator effects YAML (none: the real robot)')
    parser.add_argument('--no-bag', action='store_true', help='write only CSV + YAML')
    _options.add_noise_arguments(parser)


def run(args) -> int:
    from ..nodes.recorder import RobotUnavailable
    from ._options import UsageError
    if args.attach and not args.source:
        raise UsageError('--attach needs --source (simulator, emulator or hardware)')
    if args.protocol == 'closed-loop' and args.genome is None:
        raise UsageError('the closed-loop protocol needs --genome')
    if args.samples is None:
        args.samples = 10 if args.protocol == 'sweep' else 60
    for name in ('samples', 'episodes', 'steps', 'turn_repeats', 'sweep_passes'):
        if getattr(args, name) < 1:
            raise UsageError(f'--{name.replace("_", "-")} must be >= 1, got '
                             f'{getattr(args, name)}')
    if args.turn_rest < 10:
        raise UsageError(f'--turn-rest must be >= 10 (a turn is timed over the readings '
                         f'around it), got {args.turn_rest}')
    if not 0 < args.sweep_step <= 180:
        raise UsageError(f'--sweep-step must be in (0, 180] degrees, got {args.sweep_step}')
    if not args.period > 0:
        raise UsageError(f'--period must be > 0, got {args.period}')
    try:
        rec, session = record(args)
    except RobotUnavailable as exc:
        raise UsageError(str(exc)) from None
    except Interrupted as stop:
        if stop.recording is None:
            raise
        _write(args, stop.recording, stop.session)
        print(f'interrupted: the {len(np.unique(stop.recording.episode))} finished episodes '
              f'are saved', file=sys.stderr)
        return 130
    return _write(args, rec, session)


def _write(args, rec: Recording, session: dict) -> int:
    csv_path, yaml_path = write_csv(rec, args.out)
    written = [csv_path, yaml_path]
    if not args.no_bag:
        from ..recording.bag import write_bag
        written.append(write_bag(rec, bag_path(args.out), namespace=session['namespace'],
                                 overwrite=True, start_ns=session['start_ns']))
    lost = rec.manifest.get('lost_steps', [])
    print(f'{len(rec)} samples in {len(np.unique(rec.episode))} episodes; '
          f'{session["resent"]} resent readings kept once; {len(lost)} steps lost'
          + (f' (first: episode {lost[0][0]}, step {lost[0][1]})' if lost else ''))
    print('-> ' + ', '.join(str(p) for p in written))
    return 0 if not lost else 1


class Interrupted(KeyboardInterrupt):
    """Stopped by a signal; ``recording`` holds the episodes finished before (or None)."""

    def __init__(self, recording: Recording | None, session: dict):
        super().__init__()
        self.recording, self.session = recording, session


class _Episodes:
    """The finished episodes of a session, so that a stop keeps them."""

    def __init__(self):
        self.parts, self.lost, self.manifest = [], [], None

    def recording(self) -> Recording | None:
        if not self.parts:
            return None
        self.manifest['lost_steps'] = self.lost
        return concatenate(self.parts, self.manifest)


def record(args, context=None, robot=None) -> tuple[Recording, dict]:
    """Run the protocol; returns the recording and facts about the session.

    Stopped by Ctrl-C or SIGTERM it raises ``Interrupted`` with the episodes finished so far.

    ``context`` is an initialised rclpy Context (default: a new one); ``robot``
    an in-process robot node to record instead of the one ``args`` names.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    from ..nodes.recorder import Recorder
    from ..nodes.robot_parameters import RobotParameters
    own = context is None
    if own:
        context = Context()
        rclpy.init(context=context)
    created, close = [], (lambda: None)
    executor = SingleThreadedExecutor(context=context)
    try:
        if args.attach and robot is None:
            namespace = args.attach.rpartition('/')[0]
            robot_name, source = args.attach, args.source
        else:
            if robot is None:
                robot, close = start_robot(args.robot, context, args)
                created.append(robot)
            executor.add_node(robot)
            namespace, robot_name = robot.get_namespace(), robot.get_fully_qualified_name()
            source = args.source or args.robot.partition('-')[0]
        node = Node('recorder', namespace=namespace or '/', context=context)
        created.append(node)
        executor.add_node(node)
        recorder = Recorder(node, args.timeout, args.period if args.pace else 0.0)
        params = RobotParameters(node, executor, robot_name, args.timeout)
        recorder.wait_for_robot(executor, args.timeout)
        start_ns = time.time_ns()
        protocol = {'stationary': _stationary, 'sweep': _stationary, 'turns': _turns,
                    'closed-loop': _closed_loop}[args.protocol]
        done = _Episodes()
        session = (lambda: {'start_ns': start_ns, 'resent': recorder.resent,
                            'dropped': dict(recorder.dropped), 'namespace': namespace})
        try:
            protocol(args, recorder, executor, params, source, done)
        except KeyboardInterrupt:
            partial = done.recording()
            if partial is not None:
                partial.manifest['interrupted'] = True
            raise Interrupted(partial, session()) from None
        finally:
            params.restore()
        return done.recording(), session()
    finally:
        executor.shutdown()
        for n in created:
            n.destroy_node()
        close()
        if own:
            context.try_shutdown()


def _base_manifest(args, params, source: str, protocol: str) -> dict:
    manifest = {'format': FORMAT, 'source': source, 'sample_period_s': args.period,
                'protocol': protocol, 'conditions': {},
                'recorded_at': datetime.now(timezone.utc).isoformat(timespec='seconds'),
                'robot_node': params.robot}
    if source == 'simulator':
        noise = params.get(['noise_model', 'dependent_level', 'independent_level',
                            'dependence_groups', 'distribution'])
        manifest['noise'] = noise
    return manifest


def _stationary(args, recorder, executor, params, source, done: _Episodes) -> None:
    from . import _identify
    conditions = parse_conditions(args.conditions)
    manifest = _base_manifest(args, params, source, 'stationary')
    if args.protocol == 'sweep':
        manifest.update(sweep_step_deg=args.sweep_step, sweep_passes=args.sweep_passes)

        def headings(world: dict) -> list:
            return _identify.sweep_headings(args.sweep_step, world, args.sweep_passes)
    else:
        def headings(world: dict) -> list:
            return list(args.headings)
    manifest.update(conditions=conditions, samples_per_episode=args.samples, headings_deg=(
        list(args.headings) if args.protocol == 'stationary' else sorted(
            {h for w in conditions.values() for h in headings(w)})))
    _identify.stationary(args, recorder, executor, params, manifest, conditions, headings,
                         hold_still, done)


def _turns(args, recorder, executor, params, source, done: _Episodes) -> None:
    from . import _identify
    conditions = named_conditions()
    if args.condition not in conditions:
        raise ValueError(f'unknown condition {args.condition!r}; known: {sorted(conditions)}')
    manifest = _base_manifest(args, params, source, 'closed_loop')
    _identify.turns(args, recorder, executor, params, manifest, conditions[args.condition],
                    done)


def _closed_loop(args, recorder, executor, params, source, done: _Episodes) -> None:
    from .evolve import load_genome
    genome = network.check_genomes(load_genome(args.genome))[0]
    conditions = named_conditions()
    if args.condition not in conditions:
        raise ValueError(f'unknown condition {args.condition!r}; known: {sorted(conditions)}')
    manifest = _base_manifest(args, params, source, 'closed_loop')
    manifest.update(conditions={args.condition: conditions[args.condition]},
                    genome=genome.tolist())
    task = params.get(['perturb_every', 'perturbation_deg'])
    params.set({'steps': args.steps, **conditions[args.condition]})
    manifest['task'] = {'steps': args.steps, **task}
    policy = genome_policy(genome)
    done.manifest = manifest
    for episode in range(args.episodes):
        log = recorder.record_episode(executor, episode, args.seed + episode, args.steps,
                                      policy)
        done.lost += [[episode, s] for s in log.lost]
        done.parts.append(log.recording(args.condition, manifest, None, acted=True))
