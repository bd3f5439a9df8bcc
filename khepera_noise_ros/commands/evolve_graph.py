"""Evolve through the ROS 2 node graph: simulator, controller and evolution_manager in one
process, on one executor, exchanging every reading and command over topics.

The nodes read their parameters from --params-file (a ROS 2 parameter file such
as config/sim_comb5.yaml, with a section per node); the options below override
it.  The result equals the core's evolution (core.evolution with
CoreEvaluator; trial i with the EA seed seed + i), and the JSON record is the
evolution_manager's.  docs/nodes.md shows how to run the same nodes as
separate processes.
"""
from __future__ import annotations

from pathlib import Path
import sys
import time

from ._options import UsageError

NAME = 'graph-evolve'
HELP = 'evolve through simulator, controller and evolution_manager nodes in one process'


def add_arguments(parser) -> None:
    parser.add_argument('--params-file', type=Path, metavar='YAML',
                        help='ROS 2 parameter file for the nodes, e.g. config/sim_comb5.yaml')
    g = parser.add_argument_group('overrides of the evolution_manager parameters')
    g.add_argument('--phase', type=int, choices=(1, 2))
    g.add_argument('--population', type=int)
    g.add_argument('--generations', type=int)
    g.add_argument('--trials', type=int, help='independent runs, one robot each per step')
    g.add_argument('--seed', type=int, help='seed of the EA (trial i: seed + i)')
    g.add_argument('--seed-results', type=Path, metavar='JSON',
                   help='seed the population with the best of an earlier results file')
    g.add_argument('--results', type=Path, metavar='JSON', help='where to write the record')
    parser.add_argument('--steps', type=int, help='override the simulator steps per episode')
    parser.add_argument('--namespace', default='',
                        help='put the three nodes in this namespace (keeps concurrent runs on '
                             'one ROS domain apart)')
    parser.add_argument('--log-level', default='info',
                        choices=('debug', 'info', 'warn', 'error'))


def run(args) -> int:
    import rclpy
    from rclpy.context import Context

    from ..nodes.graph import EpisodeFailed
    from ..nodes.local_graph import local_graph
    from ..nodes.runtime import events_executor

    if args.params_file is not None and not args.params_file.is_file():
        raise FileNotFoundError(f'parameter file {args.params_file} not found')
    manager = {name: value for name, value in (
        ('phase', args.phase), ('population', args.population),
        ('generations', args.generations), ('trials', args.trials), ('seed', args.seed),
        ('seed_results', args.seed_results and str(args.seed_results)),
        ('results_path', args.results and str(args.results))) if value is not None}
    simulator = {} if args.steps is None else {'steps': args.steps}
    cli_args = ([] if args.params_file is None
                else ['--ros-args', '--params-file', str(args.params_file)])
    context = Context()
    rclpy.init(context=context, args=['--ros-args', '--log-level', args.log_level])
    try:
        with local_graph(context, simulator=simulator, manager=manager, cli_args=cli_args,
                         namespace=args.namespace, thread=False, trace=False,
                         executor_class=events_executor) as graph:
            start = time.monotonic()
            record = graph.manager.run()
            seconds = time.monotonic() - start
            steps = graph.robot.values['steps']
            path = graph.manager.values['results_path']
    except EpisodeFailed as exc:
        print(f'khepera-noise {NAME}: {exc}', file=sys.stderr)
        return 1
    except TimeoutError as exc:
        raise UsageError(str(exc)) from None
    finally:
        context.try_shutdown()
    print(f"best fitness {record['best_fitness']:.4f} (trial {record['best_trial']}, "
          f"generation {record['best_generation']}); {record['evaluations']} evaluations in "
          f"{record['episodes']['started']} episodes, {seconds:.1f} s "
          f"({record['evaluations'] * steps / seconds:.0f} robot-steps/s)"
          + (f'; written to {path}' if path else ''))
    return 0
