"""Evaluations and evolutions split across several worker pairs, with faults."""
from __future__ import annotations

from contextlib import contextmanager
import os
import signal
import subprocess
import sys
import time
from typing import Callable, Iterator

import numpy as np
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter

from khepera_noise_ros.core import evolution
from khepera_noise_ros.core.evaluation import CoreEvaluator
from khepera_noise_ros.core.task import Task
from khepera_noise_ros.nodes import protocol, schedule, worker_pair
from khepera_noise_ros.nodes.evolution_manager import MANAGER_SPECS, EvolutionManager
from khepera_noise_ros.nodes.graph import GraphEvaluator
from khepera_noise_ros.nodes.runtime import events_executor, spinning
from khepera_noise_ros.nodes.params import Spec, overrides
from khepera_noise_ros.nodes.simulator import Simulator
from khepera_noise_ros.nodes.discovery import discover
from khepera_noise_ros.nodes.episode import Chunk
from khepera_noise_ros.nodes.workers import WorkerState
from khepera_noise_ros.testing.probe import controller, manager, simulator, wait_for

STEPS = 15
CORE = CoreEvaluator(task=Task(steps=STEPS))
RNG = np.random.default_rng(8)
GENOMES = RNG.uniform(-2, 2, (11, 20))
SEEDS = RNG.integers(0, 2 ** 53, 11)


def pairs(context, namespaces, robot=simulator) -> list[Node]:
    """A robot node and a controller in each namespace."""
    return [node for ns in namespaces
            for node in (robot(context, cli_args=['--ros-args', '-r', f'__ns:={ns}'],
                               steps=STEPS),
                         controller(context, cli_args=['--ros-args', '-r', f'__ns:={ns}']))]


def named_manager(context, name: str, **values) -> EvolutionManager:
    values = {'results_path': '', 'ready_timeout_s': 20.0, **values}
    return EvolutionManager(name, context=context,
                            parameter_overrides=overrides(MANAGER_SPECS, values))


def core_evolution(config, seed, trials):
    eas = [evolution.SteadyStateEA(config, seed + i) for i in range(trials)]
    evolution.evolve(eas, CORE)
    return eas


def assert_same_evolution(record, eas):
    for trial, ea in zip(record['trials'], eas):
        assert trial['best_genome'] == ea.best_genome.tolist()
        assert trial['best_fitness'] == ea.best_fitness
        assert trial['history'] == [vars(g) for g in ea.history]


def test_the_split_makes_every_worker_finish_together_within_its_capacity():
    # equal latencies: in proportion to speed (ties to the earlier worker)
    assert schedule.shares(10, [(0.0, 1.0), (0.0, 1.0), (0.0, 0.5)]) == [3, 2, 5]
    # the slow-to-start worker would finish later even with no robot: it gets none
    assert schedule.shares(4, [(0.001, 1e-4), (0.05, 1e-6)]) == [4, 0]
    assert schedule.shares(400, [(0.001, 1e-4), (0.002, 1e-4)]) == [205, 195]
    assert schedule.pieces(3, 10, 3) == [(3, 6), (6, 9), (9, 10)]
    assert schedule.pieces(3, 10, None) == [(3, 10)]
    assert schedule.plan(0, 9, [((0.0, 1.0), None), ((0.0, 2.0), 2)]) == [[(0, 6)],
                                                                          [(6, 8), (8, 9)]]
    with pytest.raises(ValueError, match='cost per robot > 0'):
        schedule.shares(4, [(0.0, 1.0), (0.0, 0.0)])


def test_the_cost_of_a_step_is_fitted_as_latency_plus_a_cost_per_robot():
    cost = schedule.Cost()
    assert cost.model is None
    cost.add(4, 0.001 + 4 * 2e-5)
    assert cost.model == pytest.approx((0.0, (0.001 + 4 * 2e-5) / 4))   # one size: per robot
    for robots in (1, 9, 2, 30):
        cost.add(robots, 0.001 + robots * 2e-5)
    assert cost.model == pytest.approx((0.001, 2e-5))


def test_an_evolution_gives_the_same_result_on_one_two_or_four_workers(ros_context):
    namespaces = ['/w0', '/w1', '/w2', '/w3']
    records = {}
    with spinning(pairs(ros_context, namespaces), ros_context, thread=False,
                  executor_class=events_executor) as executor:
        for n, workers in {1: ['/w0'], 2: ['/w0', '/w1'], 4: ['/w*']}.items():
            mgr = named_manager(ros_context, f'manager{n}', workers=workers, population=6,
                                generations=2, trials=2, seed=4)
            executor.add_node(mgr)
            try:
                mgr.evaluator.executor = executor   # spun by the evaluator while it waits
                mgr.evaluator.wait_ready()
                if n == 4:
                    assert wait_for(lambda: discover(mgr, ['/w*']) == namespaces)
                records[n] = mgr.run()
            finally:
                executor.remove_node(mgr)
                mgr.destroy_node()
    eas = core_evolution(evolution.EAConfig(population=6, generations=2), 4, 2)
    for n, record in records.items():
        assert_same_evolution(record, eas)
        assert [w['namespace'] for w in record['workers']] == namespaces[:n]
        assert all(w['robots'] > 0 and w['dropped'] is None for w in record['workers']), n
        assert record['episodes']['restarted'] == 0
    assert records[4]['episodes']['started'] > records[1]['episodes']['started']


class PortedSimulator(Simulator):
    """A simulator that, like a hardware bridge, has as many robots as it has ports."""

    EXTRA_SPECS = Simulator.EXTRA_SPECS + (
        Spec('ports', ['a', 'b'], 'One per robot.', type_=Parameter.Type.STRING_ARRAY),)


def ported(context, cli_args=None, **values):
    return PortedSimulator(context=context, cli_args=cli_args, parameter_overrides=overrides(
        PortedSimulator.parameter_specs(), values))


def test_a_batch_larger_than_a_worker_holds_runs_as_several_episodes(ros_context):
    """/b has two ports; the evaluator allows at most three robots on any worker."""
    nodes = pairs(ros_context, ['/a']) + pairs(ros_context, ['/b'], robot=ported)
    client = Node('client', context=ros_context)
    sizes = {'/a': [], '/b': []}
    for ns, seen in sizes.items():
        client.create_subscription(
            protocol.Float64MultiArray, f'{ns}/episode_start',
            lambda msg, seen=seen: seen.append(len(protocol.unpack_episode_start(msg)[1])),
            protocol.QOS)
    evaluator = GraphEvaluator(client, workers=['/a', '/b'], capacity=3, trace=True)
    with spinning(nodes + [client], ros_context):
        evaluator.wait_ready()
        fitness = evaluator(GENOMES, SEEDS)
        trace = evaluator.trace(GENOMES[:7], SEEDS[:7])
        assert wait_for(lambda: sum(sum(s) for s in sizes.values()) == 11 + 7)
    np.testing.assert_array_equal(fitness, CORE(GENOMES, SEEDS))
    expected = CORE.trace(GENOMES[:7], SEEDS[:7])
    for name in ('bearing_deg', 'readings', 'direction', 'power'):
        np.testing.assert_array_equal(getattr(trace, name), getattr(expected, name), name)
    assert max(sizes['/a']) <= 3 and max(sizes['/b']) <= 2 and sizes['/b']
    assert evaluator.workers['/b'].capacity == 2 and evaluator.restarts == 0


@contextmanager
def worker_processes(context, namespaces) -> Iterator[tuple[dict[str, subprocess.Popen],
                                                            Callable[[str], subprocess.Popen]]]:
    """A worker_pair process per namespace, on the test's ROS domain, and a function that
    starts another; all are stopped at the end."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(context.get_domain_id()),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    procs: dict[str, subprocess.Popen] = {}

    def start(ns: str) -> subprocess.Popen:
        if ns in procs:                 # the process it replaces: ended and reaped
            procs[ns].kill()
            procs[ns].wait()
        procs[ns] = subprocess.Popen(
            [sys.executable, '-m', 'khepera_noise_ros.nodes.worker_pair', '--ros-args',
             '-r', f'__ns:={ns}', '-p', f'steps:={STEPS}', '--log-level', 'warn'], env=env)
        return procs[ns]
    try:
        for ns in namespaces:
            start(ns)
        yield procs, start
    finally:
        for proc in procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        for proc in procs.values():
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def test_worker_processes_join_late_and_a_killed_one_hands_its_work_on(ros_context, capfd):
    """Two worker processes; a third joins and is used from the next batch; then one is
    killed (SIGKILL) in the middle of an episode of an evolution, whose result stays the
    core's, with a log line that says what happened; restarted, it is used again."""
    mgr = manager(ros_context, workers=['/w*'], population=6, generations=4, trials=2,
                  seed=6, stall_timeout_s=1.0)
    with worker_processes(ros_context, ['/w0', '/w1']) as (procs, start), \
            spinning([mgr], ros_context):
        evaluator = mgr.evaluator
        assert wait_for(lambda: discover(mgr, ['/w*']) == ['/w0', '/w1'], 30)
        evaluator.wait_ready()
        np.testing.assert_array_equal(evaluator(GENOMES, SEEDS), CORE(GENOMES, SEEDS))
        start('/w2')
        assert wait_for(lambda: '/w2' in discover(mgr, ['/w*']), 30)
        evaluator.wait_ready()                  # every worker found so far is ready
        np.testing.assert_array_equal(evaluator(GENOMES, SEEDS), CORE(GENOMES, SEEDS))
        assert evaluator.workers['/w2'].robots > 0                  # used from this batch

        started, killed = evaluator.episodes, []

        def kill_mid_episode() -> bool:
            """SIGKILL whichever worker has been in an episode for a few milliseconds
            (the evaluator sees no steps: one message per episode), once the evolution
            has run two episodes."""
            running = [w for w in evaluator.workers.values() if w.episode is not None
                       and time.monotonic() - w.episode.progress > 0.003]
            if not killed and running and evaluator.episodes >= started + 2:
                procs[running[0].name].send_signal(signal.SIGKILL)
                killed.append(running[0].name)
            return bool(killed)
        finished = mgr.start()
        assert wait_for(lambda: kill_mid_episode() or finished.done(), 60)
        assert killed, 'the evolution ended before a worker could be killed'
        assert wait_for(finished.done, 60)
        record = finished.result()

        victim = evaluator.workers[killed[0]]
        start(victim.name)                      # started again, it answers: taken back
        before, deadline = victim.robots, time.monotonic() + 60
        while victim.robots == before and time.monotonic() < deadline:
            np.testing.assert_array_equal(evaluator(GENOMES, SEEDS), CORE(GENOMES, SEEDS))
        assert victim.robots > before and victim.state is not WorkerState.LOST
    eas = core_evolution(evolution.EAConfig(population=6, generations=4), 6, 2)
    assert_same_evolution(record, eas)
    dropped = {w['namespace']: w['dropped'] for w in record['workers']}
    reason = dropped.pop(killed[0])     # stalled, or (killed as it finished) silent on loading
    assert 'stalled: no fitness' in reason or 'no answer within' in reason
    assert list(dropped.values()) == [None, None]
    assert record['episodes']['restarted'] >= 1
    err = capfd.readouterr().err
    assert f'worker {killed[0]} dropped from the pool: {reason}' in err, err[-2000:]
    assert f'worker {killed[0]} answers again: back in the pool' in err


def test_worker_pair_refuses_an_unknown_argument(capsys):
    assert worker_pair.main(['worker_pair', '--simulator']) == 2
    assert "unknown argument(s) ['--simulator']; usage: worker_pair [--bridge]" in \
        capsys.readouterr().err


def test_a_worker_joins_when_its_pair_answers_leaves_on_drop_and_comes_back(ros_context):
    """JOINING until both nodes of the pair are connected and have answered a parameter
    request; LOST (with its chunks handed back) when dropped, however it answers; back
    READY once it answers again while its robot node listens."""
    evaluator_node = Node('evaluator', context=ros_context)
    worker = GraphEvaluator(evaluator_node, robot_namespace='/w').first
    assert worker.state is WorkerState.JOINING
    assert not worker.check_joined(0.5) and worker.state is WorkerState.JOINING   # no pair
    ns = ['--ros-args', '-r', '__ns:=/w']
    pair = [simulator(ros_context, cli_args=ns), controller(ros_context, cli_args=ns)]
    with spinning([evaluator_node, *pair], ros_context):
        assert wait_for(lambda: worker.check_joined(0.5), timeout=20)
        assert worker.state is WorkerState.READY
        assert not worker.check_joined(0.5)                # already READY: no news
        worker.queue.append(Chunk(0, 3))
        assert worker.drop('test') == [Chunk(0, 3)] and worker.state is WorkerState.LOST
        assert not worker.check_joined(0.5) and worker.state is WorkerState.LOST
        assert worker.record()['dropped'] == 'test'
        assert wait_for(lambda: worker.answers(0.5), timeout=20)
        worker.rejoin()
        assert worker.state is WorkerState.READY and worker.record()['dropped'] is None
