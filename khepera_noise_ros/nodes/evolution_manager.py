"""The evolution_manager node: the paper's steady-state EA, evaluated through the graph.

It runs ``core.evolution`` (phase 1: 25 x 50 generations from a random start;
phase 2: 10 x 5 seeded with a phase-1 best) with a GraphEvaluator as the
fitness function: genomes go to the controller as a parameter, episodes run
on whichever robot node ``robot_namespace`` points at, and fitness is
computed from the readings and commands seen on the topics.  ``trials``
independent runs evolve together, so each lockstep step carries one robot per
trial; trial i uses the EA seed ``seed + i``.  It
publishes the best fitness of every generation on ``best_fitness`` and writes a
JSON record at the end.
With the same seeds the result equals core.evolution with CoreEvaluator.
"""
from __future__ import annotations

from dataclasses import asdict, replace
import json
from pathlib import Path
import sys
import threading
import time
from typing import Any

import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.task import Future
from std_msgs.msg import Float64

from ..core.evolution import BEST_MODES, FITNESS_MODES, PHASE1, PHASE2, EAConfig, \
    SteadyStateEA, evolve
from ..core.network import GENES, check_genomes
from ..files import write_json
from . import spin_node
from .graph import GraphEvaluator
from .params import SEED_MAX, Spec, check_choice, current, declare, proposed

FORMAT = 'khepera-noise-evolution/1'
BEST_FITNESS = 'best_fitness'

MANAGER_SPECS = (
    Spec('phase', 1, 'Phase of the paper: 1 = population 25, 50 generations, random start; '
         '2 = population 10, 5 generations, seeded with a phase-1 best.', 1, 2),
    Spec('population', 0, 'Population size; 0 = the phase default.', 0, 100000),
    Spec('generations', -1, 'Generations after the initial one; -1 = the phase default.',
         -1, 100000),
    Spec('fitness_mode', 'stored', 'stored: evaluate each individual once, at birth; '
         'reevaluate: evaluate both members afresh in every tournament.',
         choices=FITNESS_MODES),
    Spec('best_mode', 'ever', 'ever: best single evaluation of the run; final: best of the '
         'last population; retest: last population re-evaluated, best mean.',
         choices=BEST_MODES),
    Spec('retest_episodes', 5, 'Episodes per individual when best_mode is retest.', 1, 1000),
    Spec('seed', 0, 'Seed of the EA; trial i uses seed + i (trial 0 is exactly '
         'SteadyStateEA(config, seed)).', 0, SEED_MAX),
    Spec('trials', 1, 'Independent EA runs evolved together (one robot each per step).',
         1, 10000),
    Spec('seed_genome', [], f'{GENES} genes that seed the population (phase 2); empty: '
         'seed_results, or a random start in phase 1.', type_=Parameter.Type.DOUBLE_ARRAY),
    Spec('seed_results', '', 'A results JSON of an earlier run whose best genome(s) seed the '
         'population (one per trial if it has as many trials, else its overall best).'),
    Spec('robot_namespace', '', 'Namespace of the robot node topics (light, cmd_turn, '
         'bearing, episode_start); empty: this node\'s namespace.', read_only=True),
    Spec('robot_node', '', 'Name of the robot node (for its steps parameter); empty: the '
         'node that publishes light.', read_only=True),
    Spec('controller_node', '', 'Name of the controller node whose genomes parameter is set; '
         'empty: <robot_namespace>/controller.', read_only=True),
    Spec('results_path', 'evolution_results.json', 'Where the JSON record is written at the '
         'end (atomically); empty: not written.'),
    Spec('stall_timeout_s', 2.0, 'An episode with no new message for this long is started '
         'again under a new id with the same seeds.', 0.01, 3600.0),
    Spec('max_retries', 3, 'Restarts of one episode before the evolution fails.', 0, 1000),
    Spec('ready_timeout_s', 30.0, 'How long to wait for the robot node and controller.',
         0.0, 86400.0),
)


def ea_config(values: dict[str, Any]) -> EAConfig:
    base = PHASE1 if values['phase'] == 1 else PHASE2
    check_choice('fitness_mode', values['fitness_mode'], FITNESS_MODES)
    check_choice('best_mode', values['best_mode'], BEST_MODES)
    return replace(base, population=values['population'] or base.population,
                   generations=(base.generations if values['generations'] < 0
                                else values['generations']),
                   fitness=values['fitness_mode'], best=values['best_mode'],
                   retest_episodes=values['retest_episodes'])


def _one_genome(value) -> np.ndarray:
    genes = np.asarray(value, dtype=np.float64).reshape(-1)
    if genes.size != GENES:
        raise ValueError(f'seed_genome must hold {GENES} genes, got {genes.size} values')
    return check_genomes(genes)[0]


def trial_seeds(seed: int, trials: int) -> list[int]:
    """The EA seed of each trial: seed, seed + 1, ..."""
    return [(seed + i) % (SEED_MAX + 1) for i in range(trials)]


def seed_genomes(values: dict[str, Any]) -> list[np.ndarray | None]:
    """The seed genome of each trial (None: random start)."""
    trials = values['trials']
    if len(values['seed_genome']):
        return [_one_genome(values['seed_genome'])] * trials
    if values['seed_results']:
        path = values['seed_results']
        record = json.loads(Path(path).read_text())
        if not isinstance(record, dict) or record.get('format') != FORMAT:
            raise ValueError(f'seed_results {path} is not a {FORMAT} file')
        try:
            genomes = [t['best_genome'] for t in record['trials']]
            if len(genomes) != trials:
                genomes = [record['best_genome']] * trials
        except (KeyError, TypeError) as exc:
            raise ValueError(f'seed_results {path} has no best genome: {exc!r}') from None
        return [_one_genome(g) for g in genomes]
    if values['phase'] == 2:
        raise ValueError('phase 2 starts from a phase-1 best: set seed_genome '
                         f'({GENES} genes) or seed_results (a phase-1 results file)')
    return [None] * trials


class EvolutionManager(Node):
    """Runs the EA through the graph; ``start()`` runs it in a worker thread."""

    def __init__(self, node_name: str = 'evolution_manager', bearings: bool = False,
                 **kwargs):
        """``bearings``: also observe the bearing topic, so ``evaluator.trace()`` works (the
        evolution itself needs only light and cmd_turn)."""
        super().__init__(node_name, **kwargs)
        declare(self, MANAGER_SPECS)
        self.values = current(self, MANAGER_SPECS)
        self.check_parameters(self.values)
        v = self.values
        self.evaluator = GraphEvaluator(
            self, robot_namespace=v['robot_namespace'], controller_node=v['controller_node'],
            robot_node=v['robot_node'], stall_timeout_s=v['stall_timeout_s'],
            max_retries=v['max_retries'], bearings=bearings)
        self._best_pub = self.create_publisher(Float64, BEST_FITNESS, 10)
        self.results: dict | None = None
        self.finished: Future | None = None
        self._worker: threading.Thread | None = None
        self._published = 0
        self._counts = (0, 0)
        self.add_on_set_parameters_callback(self._on_set)
        self.add_post_set_parameters_callback(self._post_set)

    @staticmethod
    def check_parameters(values: dict[str, Any]) -> None:
        ea_config(values)
        if len(values['seed_genome']):
            _one_genome(values['seed_genome'])

    def _on_set(self, params: list[Parameter]) -> SetParametersResult:
        try:
            self.check_parameters(proposed(self, MANAGER_SPECS, params))
        except ValueError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _post_set(self, params: list[Parameter]) -> None:
        """The timeouts apply at once, the rest at the next start()."""
        self.values = current(self, MANAGER_SPECS)
        self.evaluator.stall_timeout_s = self.values['stall_timeout_s']
        self.evaluator.max_retries = self.values['max_retries']

    # --- running ------------------------------------------------------------------------

    def start(self) -> Future:
        """Run the evolution in a worker thread while the executor spins this node."""
        if self._worker is not None and self._worker.is_alive():
            raise RuntimeError('an evolution is already running')
        self.finished = Future()
        self._worker = threading.Thread(target=self._run_into, args=(self.finished,),
                                        daemon=True)
        self._worker.start()
        return self.finished

    def _run_into(self, future: Future) -> None:
        try:
            future.set_result(self.run())
        except Exception as exc:            # reported through the future, and logged
            self.get_logger().error(f'evolution failed: {exc}')
            future.set_exception(exc)

    def run(self) -> dict:
        """Evolve to the end, publish and log progress, write and return the record."""
        v = dict(self.values)
        config, seeds = ea_config(v), seed_genomes(v)
        started = time.monotonic()
        self.evaluator.wait_ready(v['ready_timeout_s'])
        robot = self._robot_record()
        eas = [SteadyStateEA(config, seed=s, seed_genome=g)
               for s, g in zip(trial_seeds(v['seed'], v['trials']), seeds)]
        self.get_logger().info(
            f'evolving {len(eas)} trial(s): population {config.population}, '
            f'{config.generations} generations, robot node {self.evaluator.robot_node}')
        self._published = 0
        self._counts = (self.evaluator.episodes, self.evaluator.restarts)
        evolve(eas, self.evaluator, progress=self._progress)
        self.results = self._record(v, config, eas, robot, time.monotonic() - started)
        if v['results_path']:
            write_json(v['results_path'], self.results)
            self.get_logger().info(f"results written to {v['results_path']}")
        self.get_logger().info(f"best fitness {self.results['best_fitness']:.4f} (trial "
                               f"{self.results['best_trial']}, generation "
                               f"{self.results['best_generation']})")
        return self.results

    def _robot_record(self) -> dict:
        try:
            parameters = self.evaluator.robot_parameters()
        except TimeoutError as exc:
            self.get_logger().warning(f'the results will not list the robot parameters: {exc}')
            parameters = None
        return {'node': self.evaluator.robot_node, 'parameters': parameters}

    def _progress(self, eas: list[SteadyStateEA]) -> None:
        """Publish and log each generation once every trial has finished it."""
        while self._published < min(len(ea.history) for ea in eas):
            g = self._published
            best = max(ea.history[g].best for ea in eas)
            mean = float(np.mean([ea.history[g].mean for ea in eas]))
            self._best_pub.publish(Float64(data=best))
            episodes = self._episodes()
            self.get_logger().info(
                f'generation {g}/{eas[0].config.generations}: best {best:.4f}, mean '
                f'{mean:.4f}, {sum(ea.evaluations for ea in eas)} evaluations, '
                f"{episodes['started']} episodes, {episodes['restarted']} restarts")
            self._published += 1

    def _episodes(self) -> dict:
        """Episodes started and restarted by this run."""
        return {'started': self.evaluator.episodes - self._counts[0],
                'restarted': self.evaluator.restarts - self._counts[1]}

    def _record(self, v: dict, config: EAConfig, eas: list[SteadyStateEA], robot: dict,
                wall_time_s: float) -> dict:
        trials = [{'seed': ea_seed, 'history': [asdict(g) for g in ea.history],
                   'best_genome': ea.best_genome.tolist(), 'best_fitness': ea.best_fitness,
                   'best_generation': ea.best_generation, 'evaluations': ea.evaluations}
                  for ea_seed, ea in zip(trial_seeds(v['seed'], len(eas)), eas)]
        best = max(range(len(trials)), key=lambda i: trials[i]['best_fitness'])
        return {
            'format': FORMAT,
            'config': {'phase': v['phase'], **asdict(config), 'seed': v['seed'],
                       'trials': v['trials'], 'seed_genome': list(v['seed_genome']),
                       'seed_results': v['seed_results']},
            'robot': robot,
            'best_trial': best,
            'best_genome': trials[best]['best_genome'],
            'best_fitness': trials[best]['best_fitness'],
            'best_generation': trials[best]['best_generation'],
            'evaluations': sum(t['evaluations'] for t in trials),
            'episodes': self._episodes(),
            'wall_time_s': wall_time_s,
            'trials': trials,
        }


def main(args=None) -> int:
    return spin_node(EvolutionManager, args, until=EvolutionManager.start)


if __name__ == '__main__':
    sys.exit(main())
