"""Episodes and evolutions through simulator -> controller -> evolution_manager."""
from concurrent.futures import ThreadPoolExecutor
import json
import threading

import numpy as np
import pytest
from rclpy.parameter import Parameter

from khepera_noise_ros.core import evolution
from khepera_noise_ros.core.evaluation import CoreEvaluator
from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.core.task import Task
from khepera_noise_ros.nodes import protocol
from khepera_noise_ros.nodes.controller import Controller
from khepera_noise_ros.nodes.graph import EpisodeFailed
from khepera_noise_ros.nodes.local_graph import local_graph
from khepera_noise_ros.nodes.runtime import spinning
from khepera_noise_ros.nodes.params import overrides
from khepera_noise_ros.nodes.protocol import CMD_TURN
from khepera_noise_ros.nodes.simulator import Simulator
from khepera_noise_ros.testing.probe import Probe, controller, manager, simulator, valid, wait_for

STEPS = 20
NOISE = dict(noise_model='combination', dependent_level=0.04, independent_level=0.03,
             dependence_groups='0,1,2;3,4,5;6,7', distribution='normal')
CORE = CoreEvaluator(noise=NoiseModel('combination', 0.04, 0.03,
                                      ((0, 1, 2), (3, 4, 5), (6, 7)), 'normal'),
                     task=Task(steps=STEPS))
RNG = np.random.default_rng(5)
GENOMES = RNG.uniform(-2, 2, (6, 20))
SEEDS = RNG.integers(0, 2 ** 53, 6)


def test_an_episode_through_the_graph_equals_the_core(ros_context):
    with local_graph(ros_context, simulator={'steps': STEPS, **NOISE}) as graph:
        graph.evaluator.wait_ready()
        trace = graph.evaluator.trace(GENOMES, SEEDS)
        fitness = graph.evaluator(GENOMES[:2], SEEDS[:2])
        single = graph.evaluator(GENOMES[3:4], SEEDS[3:4])
    expected = CORE.trace(GENOMES, SEEDS)
    for name in ('bearing_deg', 'readings', 'direction', 'power', 'fitness'):
        np.testing.assert_array_equal(getattr(trace, name), getattr(expected, name), name)
    assert trace.readings.shape == (STEPS, 6, 8)
    np.testing.assert_array_equal(fitness, CORE(GENOMES[:2], SEEDS[:2]))
    np.testing.assert_array_equal(single, CORE(GENOMES[3:4], SEEDS[3:4]))
    assert graph.evaluator.restarts == 0


class FaultyController(Controller):
    """Loses its answer to step 3, answers step 5 twice and step 7 late (after a resend)."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.faults = {3: 'lose', 5: 'duplicate', 7: 'delay'}
        self.late = threading.Timer(0.3, lambda: None)

    def _on_light(self, msg):
        step = protocol.unpack_light(msg).step
        fault = self.faults.pop(step, None)
        if fault == 'delay':
            self.late = threading.Timer(0.3, super()._on_light, (msg,))
            self.late.start()
        elif fault != 'lose':
            super()._on_light(msg)
            if fault == 'duplicate':
                super()._on_light(msg)


def test_lost_duplicated_and_late_messages_do_not_change_the_result(ros_context):
    nodes = [simulator(ros_context, steps=STEPS, resend_timeout_s=0.1, **NOISE),
             controller(ros_context, cls=FaultyController), manager(ros_context)]
    with spinning(nodes, ros_context):
        evaluator = nodes[2].evaluator
        evaluator.wait_ready()
        fitness = evaluator(GENOMES[:3], SEEDS[:3])
        nodes[1].late.join()
        assert wait_for(lambda: nodes[0].dropped['stale'] >= 2)   # the duplicate, the late
    np.testing.assert_array_equal(fitness, CORE(GENOMES[:3], SEEDS[:3]))
    assert not nodes[1].faults and evaluator.restarts == 0


class HoldingController(Controller):
    """Holds its answers from ``step`` on (setting ``reached``) until ``released``."""

    step = 6

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.reached, self.released = threading.Event(), threading.Event()

    def _on_light(self, msg):
        if protocol.unpack_light(msg).step >= self.step and not self.released.is_set():
            self.reached.set()
            return
        super()._on_light(msg)


def stop(executor, node) -> None:
    """Remove and destroy a node from the executor's own thread, between two callbacks."""
    gone = threading.Event()

    def remove():
        executor.remove_node(node)
        node.destroy_node()
        gone.set()
    executor.create_task(remove)
    executor.wake()
    assert gone.wait(10)


def test_a_robot_node_restart_repeats_the_episode_with_the_same_seeds(ros_context):
    sim = simulator(ros_context, steps=STEPS, resend_timeout_s=0.1, **NOISE)
    ctrl = controller(ros_context, cls=HoldingController)
    mgr = manager(ros_context, stall_timeout_s=0.5)
    with spinning([ctrl, mgr], ros_context) as executor, ThreadPoolExecutor(1) as pool:
        executor.add_node(sim)
        mgr.evaluator.wait_ready()
        pending = pool.submit(mgr.evaluator, GENOMES[:2], SEEDS[:2])
        assert ctrl.reached.wait(10)
        stop(executor, sim)                              # the robot node dies mid-episode ...
        sim = simulator(ros_context, steps=STEPS, resend_timeout_s=0.1, **NOISE)
        executor.add_node(sim)                           # ... and comes back, knowing nothing
        ctrl.released.set()
        fitness = pending.result(timeout=30)
        stop(executor, sim)
    np.testing.assert_array_equal(fitness, CORE(GENOMES[:2], SEEDS[:2]))
    assert mgr.evaluator.restarts >= 1


class MisscoringSimulator(Simulator):
    """Reports a fitness a little off the one its messages give, for one robot."""

    def _publish(self, readings):
        if readings is None:
            self._score[1] += np.float32(0.5)
        super()._publish(readings)


def test_a_tracing_manager_refuses_a_fitness_its_messages_do_not_give(ros_context):
    """Without tracing, the fitness message is taken as it is; tracing, every step is
    observed and the episode fails with the robot and both values named."""
    sim = MisscoringSimulator(context=ros_context, parameter_overrides=overrides(
        Simulator.parameter_specs(), {'steps': STEPS, **NOISE}))
    trusting, tracing = manager(ros_context), manager(ros_context, name='tracer', trace=True,
                                                      max_retries=0)
    with spinning([sim, controller(ros_context), trusting, tracing], ros_context):
        trusting.evaluator.wait_ready()
        fitness = trusting.evaluator(GENOMES[:2], SEEDS[:2])
        tracing.evaluator.wait_ready()
        with pytest.raises(EpisodeFailed, match=r'reports fitness [0-9.]+ for robot 1 of '
                           r'episode \d+, its light and cmd_turn messages give [0-9.]+'):
            tracing.evaluator(GENOMES[:2], SEEDS[:2])
    expected = CORE(GENOMES[:2], SEEDS[:2])
    assert fitness[0] == expected[0] and fitness[1] != expected[1]


def test_an_episode_that_never_completes_fails_with_a_clear_error(ros_context):
    sim = simulator(ros_context, steps=STEPS)
    mgr = manager(ros_context, stall_timeout_s=0.2, max_retries=1)
    nodes = [controller(ros_context), mgr]
    with spinning(nodes, ros_context) as executor:
        executor.add_node(sim)
        mgr.evaluator.wait_ready()
        stop(executor, sim)
        with pytest.raises(EpisodeFailed, match='failed 2 times; last: .*Are the robot node'):
            mgr.evaluator(GENOMES[:1], SEEDS[:1])
    assert mgr.evaluator.restarts == 1


def core_evolution(config, seed, trials, seed_genomes=None, **core):
    """The same evolution in the core: trial i has the EA seed seed + i."""
    eas = [evolution.SteadyStateEA(config, seed + i, g)
           for i, g in enumerate(seed_genomes or [None] * trials)]
    evolution.evolve(eas, CoreEvaluator(task=Task(steps=STEPS), **core))
    return eas


def test_evolution_through_the_graph_improves_matches_the_core_and_writes_results(
        ros_context, tmp_path):
    """Phase 1 (two trials, batched) then phase 2 seeded from its results file."""
    phase1, phase2 = tmp_path / 'phase1.json', tmp_path / 'phase2.json'
    with local_graph(ros_context, simulator={'steps': STEPS}, manager={
            'population': 6, 'generations': 3, 'seed': 4, 'trials': 2,
            'results_path': str(phase1)}) as graph:
        probe = Probe(ros_context)
        graph.executor.add_node(probe)
        assert wait_for(lambda: graph.manager.count_subscribers('best_fitness') >= 1)
        record = _finish(graph.manager.start())
        cmd_seen = probe.count(CMD_TURN)
        assert all(r.successful for r in probe.set_parameters(
            'evolution_manager', phase=2, population=4, generations=1,
            seed_results=str(phase1), results_path=str(phase2)))
        seeded = _finish(graph.manager.start())
        assert wait_for(lambda: probe.count('best_fitness') == 4 + 2)   # one per generation
        best_fitness = [m.data for m in probe.messages('best_fitness')]
    probe.destroy_node()        # once the graph's executor has stopped spinning it

    eas = core_evolution(evolution.EAConfig(population=6, generations=3), 4, 2)
    assert json.loads(phase1.read_text()) == record
    assert record['format'] == 'khepera-noise-evolution/1'
    assert record['config']['population'] == 6 and record['config']['generations'] == 3
    assert record['robot']['node'] == '/simulator'
    assert record['robot']['parameters']['steps'] == STEPS
    for trial, ea in zip(record['trials'], eas):
        assert trial['best_genome'] == ea.best_genome.tolist()
        assert trial['best_fitness'] == ea.best_fitness
        assert trial['best_generation'] == ea.best_generation
        assert trial['history'] == [vars(g) for g in ea.history]
        assert trial['evaluations'] == 6 + 3 * 6
        assert trial['history'][-1]['best'] > trial['history'][0]['best']        # improves
    assert record['best_fitness'] == max(ea.best_fitness for ea in eas)
    assert record['episodes']['restarted'] == 0
    assert record['episodes']['started'] < record['evaluations']     # evaluations batched
    assert cmd_seen >= STEPS * record['episodes']['started']
    assert best_fitness[:4] == [max(ea.history[g].best for ea in eas) for g in range(4)]

    best = [np.array(t['best_genome']) for t in record['trials']]
    eas2 = core_evolution(evolution.EAConfig(population=4, generations=1), 4, 2, best)
    assert [t['best_genome'] for t in seeded['trials']] == [
        ea.best_genome.tolist() for ea in eas2]
    assert seeded['config']['phase'] == 2 and json.loads(phase2.read_text()) == seeded


def _finish(future, timeout: float = 60.0) -> dict:
    assert wait_for(future.done, timeout), 'the evolution did not finish'
    return future.result()


def test_phase_2_without_a_seed_genome_fails_with_the_reason(ros_context):
    with local_graph(ros_context, simulator={'steps': STEPS}, manager={
            'phase': 2, 'population': 2, 'generations': 0}) as graph:
        future = graph.manager.start()
        assert wait_for(future.done)
        with pytest.raises(ValueError, match='phase 2 starts from a phase-1 best'):
            future.result()
        assert graph.manager.set_parameters([Parameter('seed_genome', value=[0.0] * 20)])[
            0].successful
        record = _finish(graph.manager.start())             # the node is still usable
    assert record['evaluations'] == 2 and record['config']['seed_genome'] == [0.0] * 20


def test_the_manager_refuses_bad_parameters(ros_context):
    mgr = manager(ros_context)
    try:
        for name, value, words in (('fitness_mode', 'best', 'fitness_mode must be one of'),
                                   ('seed_genome', [1.0, 2.0], 'seed_genome must hold 20'),
                                   ('robot_namespace', '/other', 'read-only')):
            result = mgr.set_parameters([Parameter(name, value=value)])[0]
            assert not result.successful and words in result.reason, result.reason
    finally:
        mgr.destroy_node()


def test_no_command_is_answered_twice_by_the_wrong_genomes(ros_context):
    """The controller drops light for another number of robots than it holds genomes."""
    ctrl = controller(ros_context, genomes=GENOMES[:2].ravel().tolist())
    probe = Probe(ros_context)
    with spinning([ctrl, probe], ros_context):
        assert probe.connected(protocol.LIGHT)
        probe.publish(protocol.LIGHT, protocol.pack_light(1, 0, np.full((3, 8), 90.0)))
        probe.publish(protocol.LIGHT, protocol.pack_light(1, 1, np.full((2, 8), 90.0)))
        assert wait_for(lambda: any(b.step == 1 for b in valid(
            probe.messages(CMD_TURN), protocol.unpack_cmd_turn)))
    assert ctrl.dropped['wrong_robots'] == 1
    assert [b.step for b in valid(probe.messages(CMD_TURN), protocol.unpack_cmd_turn)] == [1]


def test_tagged_genomes_answer_their_episode_and_the_running_one_is_kept(ros_context):
    """Genomes on the topic answer only their episode (the parameter answers the others),
    each is acknowledged, genomes for other episodes never push out the running one, and
    light for an episode pushed out is dropped, not answered with the parameter."""
    from std_msgs.msg import Float64MultiArray, Int32

    from khepera_noise_ros.core import network
    from khepera_noise_ros.nodes.controller import TAGGED
    ctrl = controller(ros_context, genomes=GENOMES[:2].ravel().tolist())
    probe = Probe(ros_context)
    send = probe.create_publisher(Float64MultiArray, protocol.GENOMES, protocol.QOS)
    acks = []
    probe.create_subscription(Int32, protocol.GENOMES_LOADED, lambda m: acks.append(m.data),
                              protocol.QOS)
    readings = np.random.default_rng(1).integers(0, 526, (2, 8)).astype(float)

    def answer(episode: int, step: int):
        probe.publish(protocol.LIGHT, protocol.pack_light(episode, step, readings))
        assert wait_for(lambda: any((b.episode, b.step) == (episode, step) for b in valid(
            probe.messages(CMD_TURN), protocol.unpack_cmd_turn)))
        return next(b.values for b in valid(probe.messages(CMD_TURN), protocol.unpack_cmd_turn)
                    if (b.episode, b.step) == (episode, step))

    def expected(genomes):
        return np.column_stack(network.act(network.unpack(genomes),
                                           readings.astype(np.float32)))
    tagged = GENOMES[2:4] * -3
    with spinning([ctrl, probe], ros_context):
        assert probe.connected(protocol.LIGHT) and wait_for(
            lambda: send.get_subscription_count() >= 1)
        send.publish(protocol.pack_genomes(7, tagged))
        assert wait_for(lambda: acks == [7])
        np.testing.assert_array_equal(answer(7, 0), expected(tagged))
        np.testing.assert_array_equal(answer(8, 0), expected(GENOMES[:2]))   # the parameter
        for other in range(100, 100 + 3 * TAGGED):
            send.publish(protocol.pack_genomes(other, GENOMES[:2]))
        assert wait_for(lambda: len(acks) == 1 + 3 * TAGGED)
        np.testing.assert_array_equal(answer(7, 1), expected(tagged))          # still held
        assert sorted(ctrl._tagged) == [7] + list(range(100 + 2 * TAGGED, 100 + 3 * TAGGED))
        # a pushed-out episode is not answered with the parameter's networks, though its
        # batch fits them: those are not the genomes it was sent
        probe.publish(protocol.LIGHT, protocol.pack_light(100, 0, readings))
        assert wait_for(lambda: ctrl.dropped['forgotten'] == 1)
        assert not any(b.episode == 100 for b in valid(probe.messages(CMD_TURN),
                                                       protocol.unpack_cmd_turn))
    assert acks == [7] + list(range(100, 100 + 3 * TAGGED))


class ParameterOnlyController(Controller):
    """A controller written to the version-1 interface alone: no genomes topic."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        for sub in list(self.subscriptions):
            if sub.topic_name.endswith('/' + protocol.GENOMES):
                self.destroy_subscription(sub)


def test_a_controller_without_the_genomes_topic_is_loaded_through_its_parameter(
        ros_context):
    nodes = [simulator(ros_context, steps=STEPS, **NOISE),
             controller(ros_context, cls=ParameterOnlyController), manager(ros_context)]
    with spinning(nodes, ros_context):
        evaluator = nodes[2].evaluator
        evaluator.wait_ready()
        fitness = evaluator(GENOMES, SEEDS)
    np.testing.assert_array_equal(fitness, CORE(GENOMES, SEEDS))
    assert nodes[1].get_parameter('genomes').value.tolist() == GENOMES.ravel().tolist()


def test_a_changed_steps_is_read_again_before_the_next_episode(ros_context):
    """The evaluator keeps the robot node's steps between episodes; the node's parameter
    event has it read them again, so no episode runs (and fails) on the old value."""
    nodes = [simulator(ros_context, steps=STEPS, **NOISE), controller(ros_context),
             manager(ros_context), Probe(ros_context)]
    longer = CoreEvaluator(noise=CORE.noise, task=Task(steps=STEPS + 7))
    with spinning(nodes, ros_context):
        evaluator = nodes[2].evaluator
        evaluator.wait_ready()
        np.testing.assert_array_equal(evaluator(GENOMES, SEEDS), CORE(GENOMES, SEEDS))
        assert nodes[3].set_parameters('simulator', steps=STEPS + 7)[0].successful
        assert wait_for(lambda: evaluator.first._steps is None)
        np.testing.assert_array_equal(evaluator(GENOMES, SEEDS), longer(GENOMES, SEEDS))
        np.testing.assert_array_equal(evaluator(GENOMES, SEEDS), longer(GENOMES, SEEDS))
    assert evaluator.restarts == 0
