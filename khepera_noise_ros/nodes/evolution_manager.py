"""The evolution_manager node: the paper's steady-state EA, evaluated through the graph.

It runs ``core.evolution`` (phase 1: 25 x 50 generations from a random start;
phase 2: 10 x 5 seeded with a phase-1 best) with a GraphEvaluator as the
fitness function: genomes go to the controller as a parameter, episodes run
on the robot node ``robot_namespace`` points at, or are split across the
worker pairs ``workers`` names, and fitness is computed from the readings and
commands seen on the topics.  ``trials`` independent runs evolve together, so
each lockstep step carries one robot per trial; trial i uses the EA seed
``seed + i``.  It publishes the best fitness of every generation on
``best_fitness`` (transient local, depth 1: a late subscriber gets the latest),
checkpoints after every generation (a restarted manager resumes where it
stopped; see ``checkpoint``) and writes a JSON record at the end.  The ``~/stop``
service (std_srvs/Trigger) ends a run cleanly after the generation in progress
and its checkpoint; worker health goes on ``/diagnostics``.
With the same seeds the result equals core.evolution with CoreEvaluator,
whatever the number of workers and however often the run was interrupted.
"""
from __future__ import annotations

from dataclasses import asdict, replace
import json
import os
from pathlib import Path
import sys
import threading
import time
from typing import Any

import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.task import Future
from std_msgs.msg import Float64
from std_srvs.srv import Trigger

from ..core.evolution import BEST_MODES, FITNESS_MODES, PHASE1, PHASE2, EAConfig, \
    SteadyStateEA, evolve
from ..core.network import GENES, check_genomes
from ..files import write_json
from .runtime import spin_node
from .checkpoint import Checkpoint, checkpoint_path
from .diagnostics import Diagnostics, DropReport, OK, status, WARN
from .graph import GraphEvaluator
from .params import SEED_MAX, Spec, check_choice, current, declare, proposed
from .discovery import is_pattern

FORMAT = 'khepera-noise-evolution/1'
BEST_FITNESS = 'best_fitness'
BEST_FITNESS_QOS = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
STOP = '~/stop'


class EvolutionStopped(Exception):
    """A stop was asked for: the run ends after its generation's checkpoint."""


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
         'bearing, episode_start); empty: this node\'s namespace. Ignored when workers is '
         'set.', read_only=True),
    Spec('workers', [], 'Namespaces of the worker pairs (robot node + controller) that share '
         'the evaluations, e.g. [/w0, /w1]; fnmatch patterns such as /w* take every matching '
         'pair found in the ROS graph, before every batch. Empty: the pair in '
         'robot_namespace. Fixed at start.', type_=Parameter.Type.STRING_ARRAY),
    Spec('worker_capacity', 0, 'Most robots in one episode on a worker; a larger share is '
         'run as several episodes. 0: no limit but the ports a hardware bridge has.',
         0, 1000000),
    Spec('robot_node', '', 'Name of the robot node (for its steps parameter); empty: the '
         'node that publishes light.', read_only=True),
    Spec('controller_node', '', 'Name of the controller node whose genomes parameter is set; '
         'empty: <robot_namespace>/controller.', read_only=True),
    Spec('results_path', 'evolution_results.json', 'Where the JSON record is written at the '
         'end (atomically); empty: not written.'),
    Spec('checkpoint_path', '', 'Where the run is checkpointed after every generation '
         '(atomically; removed at the end); empty: beside results_path as '
         '<name>.checkpoint.json, or no checkpoint when results_path is empty too.'),
    Spec('resume', True, 'Continue from the checkpoint when one of the same configuration '
         'exists (one of another configuration fails the start); false: start afresh and '
         'overwrite it.'),
    Spec('stall_timeout_s', 2.0, 'An episode whose fitness is this late (after twice the time '
         "the worker's measured speed predicts for it) has failed: it is started again under a "
         'new id with the same seeds, on the other workers (this one leaves the pool) when '
         'there are any.', 0.01, 3600.0),
    Spec('max_retries', 3, 'Failures of one episode before the evolution fails.', 0, 1000),
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


def _check_writable(path: str) -> None:
    """Refuse a results path that could only fail at the end of the run, results lost."""
    target = Path(path)
    folder = target.parent if str(target.parent) else Path('.')
    if not folder.is_dir() or not os.access(folder, os.W_OK):
        raise ValueError(f'results_path {path!r}: {folder} is not a writable directory')
    if len(target.name) > os.pathconf(folder, 'PC_NAME_MAX') - 16:   # room for a temp name
        raise ValueError(f'results_path {path!r}: the file name is too long for {folder}')


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

    def __init__(self, node_name: str = 'evolution_manager', trace: bool = False,
                 **kwargs):
        """``trace``: also observe every step, so ``evaluator.trace()`` works (the
        evolution itself needs only each episode's fitness message)."""
        super().__init__(node_name, **kwargs)
        declare(self, MANAGER_SPECS)
        self.values = current(self, MANAGER_SPECS)
        self.check_parameters(self.values)
        v = self.values
        single = {} if v['workers'] else dict(
            robot_namespace=v['robot_namespace'], controller_node=v['controller_node'],
            robot_node=v['robot_node'])
        self.evaluator = GraphEvaluator(
            self, stall_timeout_s=v['stall_timeout_s'], max_retries=v['max_retries'],
            trace=trace, workers=list(v['workers']), capacity=v['worker_capacity'],
            **single)
        self._best_pub = self.create_publisher(Float64, BEST_FITNESS, BEST_FITNESS_QOS)
        self._stop = threading.Event()
        self.create_service(Trigger, STOP, self._on_stop)
        self.diagnostics = Diagnostics(self, [
            DropReport(self, lambda: dict(self.evaluator.dropped)), self._worker_health])
        self.results: dict | None = None
        self.finished: Future | None = None
        self._worker: threading.Thread | None = None
        self._published = 0
        self._counts = (0, 0)
        self._before: dict = {}             # episodes and time of the runs a checkpoint holds
        self.add_on_set_parameters_callback(self._on_set)
        self.add_post_set_parameters_callback(self._post_set)

    @staticmethod
    def check_parameters(values: dict[str, Any]) -> None:
        ea_config(values)
        if len(values['seed_genome']):
            _one_genome(values['seed_genome'])
        if values['seed_results']:
            try:        # read it now: a file that is not there fails here, not at start()
                seed_genomes(values)
            except (OSError, json.JSONDecodeError) as exc:
                raise ValueError(f"seed_results {values['seed_results']!r} cannot be read: "
                                 f'{exc}') from None
        if values['results_path']:
            _check_writable(values['results_path'])
        workers = list(values['workers'])
        for namespace in workers:
            if not namespace.strip() or namespace != namespace.strip() or (
                    not is_pattern(namespace) and workers.count(namespace) > 1):
                raise ValueError(f'workers must be distinct namespaces or patterns without '
                                 f'spaces, got {workers}')

    def _on_set(self, params: list[Parameter]) -> SetParametersResult:
        try:
            if any(p.name == 'workers' for p in params):
                # not declared read_only only because params.declare cannot give a
                # read-only parameter an empty-list default
                raise ValueError('workers is fixed at start (-p workers:=[...]); it cannot '
                                 'be changed while the node runs')
            self.check_parameters(proposed(self, MANAGER_SPECS, params))
        except ValueError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _post_set(self, params: list[Parameter]) -> None:
        """The timeouts and the capacity apply at once, the rest at the next start()."""
        self.values = current(self, MANAGER_SPECS)
        self.evaluator.stall_timeout_s = self.values['stall_timeout_s']
        self.evaluator.max_retries = self.values['max_retries']
        self.evaluator.capacity = self.values['worker_capacity']

    # --- running ------------------------------------------------------------------------

    def start(self) -> Future:
        """Run the evolution in a worker thread while the executor spins this node."""
        if self._worker is not None and self._worker.is_alive():
            raise RuntimeError('an evolution is already running')
        self.finished = Future()
        self._stop.clear()
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
        """Evolve to the end (from the checkpoint of an interrupted run of the same
        configuration, if there is one), publish and log progress, write and return the
        record."""
        v = dict(self.values)
        config, seeds = ea_config(v), seed_genomes(v)
        started = time.monotonic()
        eas = [SteadyStateEA(config, seed=s, seed_genome=g)
               for s, g in zip(trial_seeds(v['seed'], v['trials']), seeds)]
        checkpoint = self._checkpoint(v, config, eas)
        self.evaluator.wait_ready(v['ready_timeout_s'])
        robot = self._robot_record()
        self.get_logger().info(
            f'evolving {len(eas)} trial(s): population {config.population}, '
            f'{config.generations} generations, on {self._where()}')
        self._published = 0
        self._counts = (self.evaluator.episodes, self.evaluator.restarts)
        evaluate = self.evaluator if checkpoint is None else checkpoint.evaluator(self.evaluator)
        try:
            evolve(eas, evaluate,
                   progress=lambda eas: self._progress(eas, checkpoint, started))
        except EvolutionStopped as stopped:
            self._stop.clear()
            where = 'no checkpoint' if checkpoint is None else f'checkpoint {checkpoint.path}'
            self.get_logger().warning(f'evolution stopped on request after generation '
                                      f'{stopped.args[0]}; {where}')
            return {'stopped': True, 'generation': stopped.args[0],
                    'checkpoint': None if checkpoint is None else str(checkpoint.path)}
        self.results = self._record(v, config, eas, robot, self._wall_time(started),
                                    checkpoint)
        if v['results_path']:
            write_json(v['results_path'], self.results)
            self.get_logger().info(f"results written to {v['results_path']}")
        if checkpoint is not None:
            checkpoint.remove()
        self.get_logger().info(f"best fitness {self.results['best_fitness']:.4f} (trial "
                               f"{self.results['best_trial']}, generation "
                               f"{self.results['best_generation']})")
        return self.results

    def _where(self) -> str:
        workers = self.evaluator.workers
        if len(workers) == 1 and not self.evaluator.patterns:
            return f'robot node {self.evaluator.robot_node}'
        return f'workers {sorted(workers)}' + (
            f' and any matching {self.evaluator.patterns}' if self.evaluator.patterns else '')

    def _checkpoint(self, v: dict, config: EAConfig, eas: list[SteadyStateEA]
                    ) -> Checkpoint | None:
        """The run's checkpoint, loaded when it holds an interrupted run of this
        configuration and ``resume`` is set."""
        path = checkpoint_path(v['results_path'], v['checkpoint_path'])
        self._before = {}
        if path is None:
            return None
        identity = {**self._config(v, config), 'seed_genomes': [
            None if ea.seed_genome is None else ea.seed_genome.tolist() for ea in eas]}
        identity.pop('seed_results')        # the genomes it held count, not the path
        checkpoint = Checkpoint(path, identity)
        if v['resume'] and checkpoint.load():
            self._before = checkpoint.state
            self.get_logger().warning(
                f"resuming from checkpoint {path}: generation {checkpoint.state['generation']}"
                f' of {config.generations} done, {checkpoint.loaded} batches recorded')
        return checkpoint

    def _robot_record(self) -> dict:
        """The first worker's robot node and parameters; a warning for every other worker
        whose parameters differ (its episodes would not be the same)."""
        evaluator = self.evaluator
        try:
            parameters = evaluator.robot_parameters()
        except TimeoutError as exc:
            self.get_logger().warning(f'the results will not list the robot parameters: {exc}')
            parameters = None
        for worker in list(evaluator.workers.values())[1:]:
            try:
                theirs = evaluator.robot_parameters(worker=worker)
            except TimeoutError:
                continue
            differ = sorted(k for k in set(theirs) | set(parameters or {})
                            if (parameters or {}).get(k) != theirs.get(k))
            if parameters is not None and differ:
                self.get_logger().warning(
                    f'{worker.robot_node} has other parameters than {evaluator.robot_node}: '
                    f'{", ".join(differ)}; results depend on the split if these matter')
        return {'node': evaluator.robot_node, 'parameters': parameters}

    def _progress(self, eas: list[SteadyStateEA], checkpoint: Checkpoint | None,
                  started: float) -> None:
        """Publish, log and checkpoint each generation once every trial has finished it;
        generations a checkpoint replays were published by the run that recorded them."""
        done = min(len(ea.history) for ea in eas)
        if checkpoint is not None and checkpoint.calls <= checkpoint.loaded:
            self._published = done
            return
        if done == self._published:
            return
        while self._published < done:
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
        if checkpoint is not None:
            checkpoint.save(generation=done - 1,
                            history=[[asdict(g) for g in ea.history] for ea in eas],
                            episodes=self._episodes(), wall_time_s=self._wall_time(started))
        if self._stop.is_set() and done <= eas[0].config.generations:
            raise EvolutionStopped(done - 1)

    # --- the stop service and /diagnostics ------------------------------------------------

    def _on_stop(self, request: Trigger.Request, response: Trigger.Response
                 ) -> Trigger.Response:
        """Ask the run to end after the generation in progress (and its checkpoint)."""
        if self._worker is None or not self._worker.is_alive():
            response.success, response.message = False, 'no evolution is running'
            return response
        self._stop.set()
        path = checkpoint_path(self.values['results_path'], self.values['checkpoint_path'])
        response.success = True
        response.message = ('stopping after the generation in progress; ' + (
            f'its checkpoint is {path} (start again to resume)' if path else
            'no checkpoint is configured, so a new start begins afresh'))
        self.get_logger().info(response.message)
        return response

    def _worker_health(self) -> list:
        """One status per worker pair: OK while it is in the pool, WARN once dropped."""
        statuses = []
        try:
            records = self.evaluator.worker_records()
        except RuntimeError:                # the pool changed under us: report next time
            return statuses
        for record in records:
            left = record['dropped']
            statuses.append(status(
                f"{self.get_fully_qualified_name()}: worker {record['namespace'] or '/'}",
                WARN if left else OK, f'left the pool: {left}' if left else 'in the pool',
                {k: record[k] for k in ('robot_node', 'controller_node', 'episodes',
                                        'robots', 'failures', 'robot_steps_per_s')}))
        return statuses

    def _episodes(self) -> dict:
        """Episodes started and restarted by this run (and those of the runs it resumes)."""
        before = self._before.get('episodes', {})
        return {'started': self.evaluator.episodes - self._counts[0]
                + before.get('started', 0),
                'restarted': self.evaluator.restarts - self._counts[1]
                + before.get('restarted', 0)}

    def _wall_time(self, started: float) -> float:
        return time.monotonic() - started + self._before.get('wall_time_s', 0.0)

    @staticmethod
    def _config(v: dict, config: EAConfig) -> dict:
        return {'phase': v['phase'], **asdict(config), 'seed': v['seed'],
                'trials': v['trials'], 'seed_genome': list(v['seed_genome']),
                'seed_results': v['seed_results']}

    def _record(self, v: dict, config: EAConfig, eas: list[SteadyStateEA], robot: dict,
                wall_time_s: float, checkpoint: Checkpoint | None) -> dict:
        trials = [{'seed': ea_seed, 'history': [asdict(g) for g in ea.history],
                   'best_genome': ea.best_genome.tolist(), 'best_fitness': ea.best_fitness,
                   'best_generation': ea.best_generation, 'evaluations': ea.evaluations}
                  for ea_seed, ea in zip(trial_seeds(v['seed'], len(eas)), eas)]
        best = max(range(len(trials)), key=lambda i: trials[i]['best_fitness'])
        resumed = None if not checkpoint or not checkpoint.loaded else {
            'checkpoint': str(checkpoint.path), 'batches': checkpoint.loaded,
            'generation': self._before['generation']}
        return {
            'format': FORMAT,
            'config': self._config(v, config),
            'robot': robot,
            'workers': self.evaluator.worker_records(),
            'best_trial': best,
            'best_genome': trials[best]['best_genome'],
            'best_fitness': trials[best]['best_fitness'],
            'best_generation': trials[best]['best_generation'],
            'evaluations': sum(t['evaluations'] for t in trials),
            'episodes': self._episodes(),
            'resumed': resumed,
            'wall_time_s': wall_time_s,
            'trials': trials,
        }


def main(args=None) -> int:
    return spin_node(EvolutionManager, args, until=EvolutionManager.start)


if __name__ == '__main__':
    sys.exit(main())
