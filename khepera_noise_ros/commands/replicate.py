"""Run the experiment of Meeden (1998) section 4 and write a report beside the paper's numbers.

For each noise level (5%: 3% dependent + 2% independent against 5% independent;
10%: 5% + 5% against 10%) and each of ten trials: evolve in simulation (50
generations of 25), test the best in simulation and in reality, evolve in
reality (5 generations of 10, seeded from the best) and test the new best in
reality.  Simulation runs through the node graph and reality is the robot
emulator through the hardware bridge, unless --backend core (all in process) or
--port (a real Khepera through the bridge).  With --ceiling, phase 2 also runs
again from the same bests with the full budget (steps 6-7), to show how much of
the drop real training can recover.  Every finished piece is saved as it ends:
run the same command again to resume an interrupted run.
"""
from __future__ import annotations

import argparse
import contextlib
import os
import sys
import time
from pathlib import Path

from .. import lifeline
from ..experiment import config as settings
from ..experiment import diagnosed, report, stats_report
from ..experiment.protocol import Backends, ConditionEpisodes, Experiment, batch_simulate, \
    chunked, chunked_trace, play
from ..experiment.store import Store
from ..reality.emulator import EmulatorProcess
from ..reality.khepera_robot import InProcessRobots, KheperaRobots
from ..reality.world import EmulatedWorld

HELP = "run the paper's experiment (steps 1-5, both noise models, both levels) and report"


def add_arguments(parser) -> None:
    parser.add_argument('--config', type=Path, metavar='YAML',
                        help='settings overriding the paper defaults (see config/replicate.yaml)')
    parser.add_argument('--quick', action='store_true',
                        help="the config's quick preset: fewer trials, same protocol")
    parser.add_argument('--out', type=Path,
                        help='results directory (default results/replicate, or '
                             'results/replicate-quick with --quick)')
    parser.add_argument('--fresh', action='store_true',
                        help='discard earlier results in --out instead of resuming')
    parser.add_argument('--backend', choices=('graph', 'core'), default='graph',
                        help='graph: simulator and controller nodes, emulator through the '
                             'hardware bridge; core: the same models in process (fast)')
    parser.add_argument('--port', action='append', metavar='DEV',
                        help='a real Khepera on this serial port is reality (repeatable: '
                             'one robot per port)')
    parser.add_argument('--protocol', choices=(*settings.PROTOCOLS, 'both'),
                        help="measured: 10 test episodes, bests by re-test, reset bearings "
                             "(the default); paper: section 4.4 as written; both: one run of "
                             "each (the paper's in OUT-paper)")
    parser.add_argument('--ceiling', action='store_true',
                        help='also run the ceiling arm: phase 2 again from the same phase-1 '
                             'bests with the full budget (settings key ceiling), to show how '
                             'much of the drop real training can recover; resumes a run '
                             'without it')
    parser.add_argument('--params', type=Path, metavar='FITTED_PARAMS',
                        help="a fitted_params.yaml (khepera-noise diagnose): its simulator "
                             "becomes a condition 'diagnosed' beside the paper's models "
                             '(settings key diagnosed)')
    parser.add_argument('--trials', type=int, help='trials per condition (overrides the config)')
    parser.add_argument('--seed', type=int, help="the run's seed (overrides the config)")
    parser.add_argument('--no-progress', action='store_true', help='no progress bar')


def run(args) -> int:
    if getattr(args, 'protocol', None) == 'both':
        return both_protocols(args)
    overrides = {k: v for k, v in (('trials', args.trials), ('seed', args.seed)) if v is not None}
    overrides['backend'] = backend_choice(args.backend, args.port)
    if getattr(args, 'ceiling', False):
        overrides['ceiling'] = {'enabled': True}
    if getattr(args, 'params', None) is not None:
        overrides['diagnosed'] = str(args.params)
    config = settings.load(args.config, quick=args.quick, overrides=overrides,
                           protocol=getattr(args, 'protocol', None))
    out = args.out or default_out(args.quick, getattr(args, 'protocol', None))
    store = Store(out, config.hash)
    found = store.open(config.to_yaml(), fresh=args.fresh)
    if found:
        print(f'resuming in {out}: {found} finished units and {len(store.checkpoints())} '
              f'evolutions part-way', file=sys.stderr)
    print(stats_report.power_before_run(config, store))
    started, finished = time.monotonic(), False
    try:
        with lifeline.terminate_as_interrupt(), open_backends(config, args.port) as backends, \
                Progress(enabled=not args.no_progress) as progress:
            experiment = Experiment(config, backends, store, progress)
            progress.start(experiment.episodes_left(), backends.seconds_per_episode)
            experiment.run()
            description = backends.description
        finished = True
    except KeyboardInterrupt:
        print(f'stopped; what was done is saved in {out}: run the same command again to '
              f'resume', file=sys.stderr)
        raise
    finally:
        sessions = store.record_session(time.monotonic() - started, finished, config.backend)
    analysis = report.write(out, config, store, description, sessions)
    print(report.summary(analysis), end='')
    print(f"wrote {out / 'report.md'} ({sessions[-1]['elapsed_s']:.0f} s this session, "
          f"{sum(s['elapsed_s'] for s in sessions):.0f} s in all)")
    return 0


def default_out(quick: bool, protocol: str | None) -> Path:
    name = 'results/replicate' + ('-quick' if quick else '')
    return Path(name + ('-paper' if protocol == 'paper' else ''))


def both_protocols(args) -> int:
    """The measured protocol, then the paper's, each in its own directory."""
    out = args.out or default_out(args.quick, None)
    for protocol, where in (('measured', out), ('paper', out.with_name(out.name + '-paper'))):
        print(f'--- protocol: {protocol} ({where})')
        code = run(argparse.Namespace(**{**vars(args), 'protocol': protocol, 'out': where}))
        if code:
            return code
    return 0


class Progress:
    """A tqdm bar on stderr: step, conditions, trials, generation, and the time left.

    An episode in reality costs far more than one in simulation, so the time
    left is worked out per world: episodes left times seconds per episode,
    measured as the run goes (a guess from the backend until then).
    """

    def __init__(self, enabled: bool = True):
        self.enabled = enabled
        self.bar = None
        self.generations = None
        self.world = None
        self.left: dict[str, int] = {}
        self.rate: dict[str, float] = {}
        self.spent: dict[str, list[float]] = {}     # world -> [seconds, episodes] measured
        self._since = time.monotonic()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.bar is not None:
            self.bar.close()

    def start(self, left: dict[str, int], seconds_per_episode: dict[str, float]) -> None:
        from tqdm import tqdm
        self.left, self.rate = dict(left), dict(seconds_per_episode)
        self.spent = {world: [0.0, 0] for world in left}
        self.bar = tqdm(total=sum(left.values()), unit='ep', file=sys.stderr,
                        disable=not self.enabled, dynamic_ncols=True, mininterval=0.5,
                        bar_format='{desc} {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} '
                                   'episodes [{elapsed}{postfix}]')

    def stage(self, step: int, label: str, world: str, units, generations,
              steps: int = 5) -> None:
        self.generations, self.world = generations, world
        self._since = time.monotonic()
        conditions = list(dict.fromkeys(c.name for c, _ in units))
        trials = sorted({t + 1 for _, t in units})
        span = f'trial {trials[0]}' if len(trials) == 1 else f'trials {trials[0]}-{trials[-1]}'
        names = ', '.join(conditions) if len(conditions) <= 2 else f'{len(conditions)} conditions'
        self.bar.set_description_str(f'step {step}/{steps} {label} | {names}, {span}',
                                     refresh=False)
        self._show(None)

    def advance(self, episodes: int, generation) -> None:
        now = time.monotonic()
        spent = self.spent[self.world]
        spent[0] += now - self._since
        spent[1] += episodes
        self._since = now
        self.left[self.world] -= episodes
        if spent[1]:
            self.rate[self.world] = spent[0] / spent[1]
        self._show(generation)
        self.bar.update(episodes)

    def seconds_left(self) -> float:
        return sum(n * self.rate.get(world, 0.0) for world, n in self.left.items())

    def _show(self, generation) -> None:
        parts = []
        if generation is not None and self.generations is not None:
            parts.append(f'gen {generation}/{self.generations}')
        minutes, seconds = divmod(int(self.seconds_left()), 60)
        parts.append(f'about {minutes}:{seconds:02d} left')
        self.bar.set_postfix_str(', '.join(parts), refresh=False)


# First guesses of the cost of one episode in a batch, replaced by measurement as soon as
# a world has run (measured here with --quick; a real robot: 60 turns of a few tenths of
# a second).
SECONDS_PER_EPISODE = {'graph': 0.001, 'core': 0.0005, 'emulator': 0.012, 'world': 0.004,
                       'hardware': 20.0}


def backend_choice(backend: str, ports) -> dict:
    """Which simulation and reality the options select (recorded with the settings)."""
    reality = 'hardware' if ports else ('emulator' if backend == 'graph' else 'world')
    return {'simulation': backend, 'reality': reality}


@contextlib.contextmanager
def open_backends(config: settings.ReplicateConfig, ports=None):
    """The evaluators the config's ``backend`` names; every node and port closed on exit."""
    which = config.backend
    with contextlib.ExitStack() as stack:
        if which['reality'] == 'emulator':      # first: it must outlive the bridge, and be
            ports = stack.enter_context(EmulatorProcess(_world(config))).ports  # forked pre-ROS
        ros = stack.enter_context(_Ros()) if which['simulation'] == 'graph' \
            or which['reality'] in ('emulator', 'hardware') else None
        simulate, sim_text = _simulation(config, ros)
        reality, trace, real_text = _reality(config, ros, ports)
        guess = {'simulation': SECONDS_PER_EPISODE[which['simulation']],
                 'reality': SECONDS_PER_EPISODE[which['reality']]}
        yield Backends(simulate, reality, trace, {'simulation': sim_text, 'reality': real_text},
                       guess)


def _simulation(config: settings.ReplicateConfig, ros) -> tuple:
    """(simulate, description): the paper's conditions in one batch, through the graph or
    not; the diagnosed condition (its effects) on a simulator of its own."""
    own = [c for c in config.conditions if c.effects]
    if config.backend['simulation'] == 'core':
        return (diagnosed.core(config), 'the core simulator in process, all conditions in '
                'one batch' + (' (the diagnosed condition in a batch of its own)' if own
                               else ''))
    noise = {c.key: c.noise for c in config.conditions if not c.effects}
    episodes = ConditionEpisodes(noise, config.world, config.task)
    simulate = diagnosed.combine(
        batch_simulate(ros.simulator(config, episodes), episodes),
        {c.key: ros.simulator(config, diagnosed.episodes(c, config.world, config.task),
                              name=f'simulation_{c.key}') for c in own})
    return (simulate, "the node graph: a robot node over the core simulator, each condition's "
            'noise model on its own robots of one batch, a controller node, and the fitness '
            'the robot node scores from its lockstep light and cmd_turn topics'
            + ('; the diagnosed condition on a robot node of its own over the simulator with '
               'its effects' if own else ''))


def _reality(config: settings.ReplicateConfig, ros, ports) -> tuple:
    """(evaluate, trace, description): the emulated world in process, or robots on ports."""
    if config.backend['reality'] == 'world':
        robots, capacity = _emulated_robots(config), config.reality['robots']
        return (chunked(lambda g, s: play(robots, g, s)[0], capacity),
                chunked_trace(lambda g, s: play(robots, g, s)[1], capacity),
                f'the emulated world in process ({_effects_text(config)})')
    # on a loaded machine an emulator reply can come late; a resend would read a new sample
    bridge = ros.bridge(config, ports, timeout_s=2.0 if config.backend['reality'] == 'emulator'
                        else None)
    text = (f'the robot emulator ({len(ports)} robots on pseudo-terminals, '
            f'{_effects_text(config)}) through the hardware bridge node'
            if config.backend['reality'] == 'emulator'
            else f"Khepera robot(s) on {', '.join(ports)} through the hardware bridge node")
    return chunked(bridge, len(ports)), chunked_trace(bridge.trace, len(ports)), text


def _world(config: settings.ReplicateConfig) -> EmulatedWorld:
    return EmulatedWorld(config.effects, seed=config.reality['seed'],
                         robots=config.reality['robots'], geometry=config.world,
                         start_bearing_deg=config.reality['start_bearing_deg'])


def _emulated_robots(config: settings.ReplicateConfig) -> KheperaRobots:
    return KheperaRobots(InProcessRobots(_world(config)), config.world, config.task)


def _effects_text(config: settings.ReplicateConfig) -> str:
    on = config.effects.enabled
    return 'effects: ' + (', '.join(on) if on else 'none') + \
        f", sensor noise {config.effects.sensor_noise:.0%}"


class _Ros:
    """One rclpy context and executor for every node of the run.

    The evaluators spin the executor themselves while they wait, so nothing
    runs between episodes.  Node names carry the process id, so two runs on
    one ROS domain do not answer each other's messages.
    """

    def __init__(self):
        import rclpy
        from rclpy.context import Context
        self.context = Context()
        # the nodes' routine INFO lines would bury the progress bar; warnings still show
        rclpy.init(args=['--ros-args', '--log-level', 'warn'], context=self.context)
        self.executor = _executor(self.context)
        self.nodes = []
        self.prefix = f'/khepera_noise_replicate_{os.getpid()}'

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.executor.shutdown()
        for node in self.nodes:
            node.destroy_node()
        self.context.try_shutdown()

    def _add(self, node):
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def _evaluator(self, namespace: str, robot_node: str, trace: bool = False):
        from rclpy.node import Node
        from ..nodes.controller import Controller
        from ..nodes.graph import GraphEvaluator
        self._add(Controller(context=self.context, namespace=namespace))
        client = self._add(Node('replicate', context=self.context, namespace=namespace))
        evaluator = GraphEvaluator(client, controller_node=f'{namespace}/controller',
                                   robot_node=f'{namespace}/{robot_node}',
                                   executor=self.executor, trace=trace)
        evaluator.wait_ready(timeout_s=30.0)
        return evaluator

    def simulator(self, config: settings.ReplicateConfig, episodes,
                  name: str = 'simulation'):
        """A robot node over ``episodes``, a controller, and their evaluator."""
        from ..nodes.params import overrides
        from ..nodes.robot_node import RobotNode
        namespace = f'{self.prefix}/{name}'
        geometry = {k: v for k, v in config.data['world'].items() if k != 'deg_per_power'}
        values = {**config.data['task'], **geometry}
        self._add(RobotNode('simulator', backend=episodes, context=self.context,
                            namespace=namespace,
                            parameter_overrides=overrides(RobotNode.parameter_specs(), values)))
        return self._evaluator(namespace, 'simulator')

    def bridge(self, config: settings.ReplicateConfig, ports, timeout_s: float | None = None):
        """The hardware bridge node on ``ports``, a controller, and their evaluator."""
        from ..nodes.hardware_bridge import HardwareBridge
        from ..nodes.params import overrides
        namespace = f'{self.prefix}/reality'
        values = {**config.data['task'], **config.data['world'], 'ports': list(ports),
                  'autostart': True}
        if timeout_s is not None:
            values['timeout_s'] = timeout_s
        self._add(HardwareBridge(context=self.context, namespace=namespace,
                                 parameter_overrides=overrides(HardwareBridge.parameter_specs(),
                                                               values)))
        return self._evaluator(namespace, 'hardware_bridge', trace=True)


def _executor(context):
    """rclpy's EventsExecutor where there is one (about twice as fast per lockstep step)."""
    try:
        from rclpy.experimental import EventsExecutor
        return EventsExecutor(context=context)
    except ImportError:
        from rclpy.executors import SingleThreadedExecutor
        return SingleThreadedExecutor(context=context)
