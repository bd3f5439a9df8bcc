"""Evaluating genomes through the node graph: the topic counterpart of CoreEvaluator.

``GraphEvaluator(genomes, seeds)`` loads the genomes into the controller (its
``genomes`` parameter, through the SetParameters service), starts one batched
episode on the robot node, and computes each genome's fitness from the light
and cmd_turn messages it observes, with the core's ``step_fitness``, in the
same float32 arithmetic as ``core.task.run``.  So for the same genomes, noise
model and per-robot seeds it returns exactly the core's numbers.

An episode that stalls (no new message for ``stall_timeout_s``: a node died or
restarted) or that breaks the protocol (two different messages with the same
tag, a wrong robot count) is started again under a fresh episode id with the
same seeds, so the result does not change; after ``max_retries`` it fails with
``EpisodeFailed``.  Messages tagged with another episode are ignored, so a
reading is never paired with the wrong step's command.

It waits in one of two ways: when another thread spins the node's executor
(the evolution_manager node, a script that spins in the background), on an
event the callbacks set; when given ``executor``, by spinning it itself.
"""
from __future__ import annotations

import array
from contextlib import contextmanager
from dataclasses import dataclass
import secrets
import threading
import time
from typing import Callable, Iterator

import numpy as np
from rcl_interfaces.msg import Parameter as ParameterMsg, ParameterType, ParameterValue
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter_client import AsyncParameterClient
from std_msgs.msg import Float64MultiArray, Int32MultiArray

from ..core.khepera import SENSORS
from ..core.network import GENES, check_genomes
from ..core.task import Trace, step_fitness
from . import Dropped, protocol
from .protocol import BEARING, CMD_TURN, EPISODE_START, LIGHT


class EpisodeFailed(RuntimeError):
    """An episode could not be completed through the graph."""


def episode_fitness(readings: np.ndarray, power: np.ndarray) -> np.ndarray:
    """Mean step fitness, summed in float32 step by step exactly as core.task.run does.

    readings: (steps, B, 8) float32; power: (steps, B).
    """
    total = np.zeros(readings.shape[1], np.float32)
    for step_readings, step_power in zip(readings, power):
        total += step_fitness(step_readings.T, step_power)
    return (total / len(readings)).astype(np.float64)


class EpisodeIds:
    """Episode ids that count up from a random start, so that two managers sharing a
    robot node almost surely use different ids."""

    def __init__(self):
        self._next = secrets.randbelow(protocol.MAX_EPISODE)

    def __next__(self) -> int:
        self._next = (self._next + 1) % protocol.MAX_EPISODE
        return self._next


class _Episode:
    """What the evaluator has observed of one episode; filled by the subscription callbacks.

    Each topic's values go straight into a preallocated (steps, B, columns) array, in the
    dtype the core computes with (readings float32), so that nothing is stacked at the end.
    """

    LAYOUT = {LIGHT: (SENSORS, np.float32), CMD_TURN: (2, np.int32), BEARING: (1, np.float64)}

    def __init__(self, episode: int, robots: int, steps: int, topics: tuple[str, ...]):
        self.episode, self.robots, self.steps = episode, robots, steps
        self.values = {t: np.empty((steps, robots, self.LAYOUT[t][0]), self.LAYOUT[t][1])
                       for t in topics}
        self.seen = {t: np.zeros(steps, bool) for t in topics}
        self.error: str | None = None
        self.complete = False
        self.progress = time.monotonic()
        self._count = 0

    @property
    def finished(self) -> bool:
        return self.complete or self.error is not None

    @property
    def next_step(self) -> int:
        """The first step some message is still missing for."""
        return min(int(np.argmin(seen)) if not seen.all() else self.steps
                   for seen in self.seen.values())

    def add(self, topic: str, step: int, values: np.ndarray) -> None:
        if self.finished or (topic == BEARING and step == self.steps):   # final heading
            return
        if values.shape[0] != self.robots:
            self.error = (f'{topic} ({self.episode}, {step}) has {values.shape[0]} robots, '
                          f'the episode has {self.robots}')
        elif step >= self.steps:
            self.error = (f'{topic} for step {step}, but the robot node has steps = '
                          f'{self.steps} (was it changed during the episode?)')
        elif not self.seen[topic][step]:
            self.values[topic][step] = values
            self.seen[topic][step] = True
            self.progress = time.monotonic()
            self._count += 1
            self.complete = self._count == len(self.values) * self.steps
        elif not np.array_equal(self.values[topic][step],
                                values.astype(self.values[topic].dtype)):
            self.error = (f'two different {topic} messages for ({self.episode}, {step}): '
                          'a node answered twice with different data')


class GraphEvaluator:
    """``(genomes (n, 20), seeds (n,)) -> fitness (n,)`` through a robot node and controller.

    With ``bearings=False`` it does not subscribe to ``bearing``: one message less to
    take per step (fitness needs only light and cmd_turn), but no ``trace()``.
    """

    def __init__(self, node: Node, robot_namespace: str = '', controller_node: str = '',
                 robot_node: str = '', stall_timeout_s: float = 2.0, max_retries: int = 3,
                 executor: Executor | None = None, bearings: bool = True):
        self.node = node
        self.stall_timeout_s = stall_timeout_s
        self.max_retries = max_retries
        self.executor = executor
        ns = robot_namespace.rstrip('/')
        self.topics = {n: self._in(ns, n) for n in (LIGHT, CMD_TURN, BEARING, EPISODE_START)}
        self.controller_node = controller_node or self._in(ns, 'controller')
        self.robot_node = robot_node
        self.dropped = Dropped(node)
        self.episodes = 0           # episode attempts started
        self.restarts = 0
        self._ids = EpisodeIds()
        self._wake = threading.Event()
        self._current: _Episode | None = None
        self._controller = AsyncParameterClient(node, self.controller_node)
        self._robot: AsyncParameterClient | None = None
        self._start_pub = node.create_publisher(Float64MultiArray, self.topics[EPISODE_START],
                                                protocol.QOS)
        observed = ((LIGHT, Float64MultiArray, protocol.unpack_light),
                    (CMD_TURN, Int32MultiArray, protocol.unpack_cmd_turn),
                    (BEARING, Float64MultiArray, protocol.unpack_bearing))[:3 if bearings else 2]
        self._observed = tuple(topic for topic, _, _ in observed)
        for topic, msg_type, unpack in observed:
            node.create_subscription(msg_type, self.topics[topic],
                                     self._observer(topic, unpack), protocol.QOS, raw=True)

    @staticmethod
    def _in(ns: str, name: str) -> str:
        return f'{ns}/{name}' if ns else name

    # --- public ------------------------------------------------------------------------

    def __call__(self, genomes, seeds) -> np.ndarray:
        episode = self._run(genomes, seeds)
        if episode is None:
            return np.empty(0)
        return episode_fitness(episode.values[LIGHT], episode.values[CMD_TURN][..., 1])

    def trace(self, genomes, seeds) -> Trace:
        """Per-step record of the episode ``__call__`` would score."""
        if BEARING not in self._observed:
            raise ValueError('this evaluator was made with bearings=False, so it does not see '
                             'the bearing topic a trace needs')
        episode = self._run(genomes, seeds)
        if episode is None:
            raise ValueError('trace() needs at least one genome')
        cmd = episode.values[CMD_TURN]
        return Trace(episode.values[BEARING][..., 0], episode.values[LIGHT],
                     np.ascontiguousarray(cmd[..., 0]), np.ascontiguousarray(cmd[..., 1]))

    def robot_parameters(self, timeout_s: float = 5.0) -> dict:
        """The robot node's parameters by name (for the record of a run)."""
        names_f = self._robot_client().list_parameters()
        if not self._wait(names_f.done, timeout_s):
            raise TimeoutError(f'no answer from {self.robot_node}/list_parameters')
        names = list(names_f.result().result.names)
        values_f = self._robot_client().get_parameters(names)
        if not self._wait(values_f.done, timeout_s):
            raise TimeoutError(f'no answer from {self.robot_node}/get_parameters')
        return {n: _python(v) for n, v in zip(names, values_f.result().values)}

    def wait_ready(self, timeout_s: float = 30.0) -> None:
        """Block until a robot node and a controller are connected, else TimeoutError."""
        if not self._wait(lambda: not self._missing(), timeout_s):
            raise TimeoutError(f'after {timeout_s} s still waiting for: '
                               + '; '.join(self._missing()))
        robot = self._robot_client()
        if not self._wait(robot.services_are_ready, timeout_s):
            raise TimeoutError(f'the parameter services of {self.robot_node} did not appear')

    # --- waiting -------------------------------------------------------------------------

    def _wait(self, done: Callable[[], bool], timeout_s: float | Callable[[], float]) -> bool:
        """Wait until done(); ``timeout_s`` may be a function giving the current deadline."""
        start = time.monotonic()
        deadline = timeout_s if callable(timeout_s) else (lambda: start + timeout_s)
        while not done():
            left = deadline() - time.monotonic()
            if left <= 0:
                return False
            if self.executor is not None:
                self.executor.spin_once(timeout_sec=min(left, 0.05))
            else:
                self._wake.wait(min(left, 0.05))
                self._wake.clear()
        return True

    def _missing(self) -> list[str]:
        node, t = self.node, self.topics
        missing = []
        if self._start_pub.get_subscription_count() < 1:
            missing.append(f'a robot node subscribed to {t[EPISODE_START]}')
        if node.count_publishers(t[LIGHT]) < 1 or node.count_subscribers(t[CMD_TURN]) < 2:
            missing.append(f'a robot node publishing {t[LIGHT]} and subscribed to '
                           f'{t[CMD_TURN]}')
        if node.count_publishers(t[CMD_TURN]) < 1 or node.count_subscribers(t[LIGHT]) < 2:
            missing.append(f'a controller publishing {t[CMD_TURN]} and subscribed to '
                           f'{t[LIGHT]}')
        if not self._controller.services_are_ready():
            missing.append(f'the parameter services of {self.controller_node}')
        return missing

    def _robot_names(self) -> list[str]:
        """Nodes that publish light and subscribe to episode_start, once discovery has
        named them."""
        node = self.node

        def names(infos) -> set[str]:
            return {f"{i.node_namespace.rstrip('/')}/{i.node_name}" for i in infos}
        light = names(node.get_publishers_info_by_topic(
            node.resolve_topic_name(self.topics[LIGHT])))
        start = names(node.get_subscriptions_info_by_topic(
            node.resolve_topic_name(self.topics[EPISODE_START])))
        if any('_NODE_NAME_UNKNOWN_' in n for n in light | start):
            return []
        return sorted(light & start)

    def _robot_client(self) -> AsyncParameterClient:
        """The robot node's parameter client; its name is found from who publishes light."""
        if self._robot is None:
            if not self.robot_node:
                if not self._wait(self._robot_names, self.stall_timeout_s):
                    raise EpisodeFailed(f'no robot node publishes {self.topics[LIGHT]} and '
                                        f'subscribes to {self.topics[EPISODE_START]}')
                names = self._robot_names()
                if len(names) != 1:
                    raise EpisodeFailed(f'expected one robot node (publishing '
                                        f'{self.topics[LIGHT]}, subscribed to '
                                        f'{self.topics[EPISODE_START]}), found {names}; name '
                                        'it with robot_node')
                self.robot_node = names[0]
            self._robot = AsyncParameterClient(self.node, self.robot_node)
        return self._robot

    # --- one batched episode -----------------------------------------------------------

    def _run(self, genomes, seeds) -> _Episode | None:
        genomes = check_genomes(genomes) if np.size(genomes) else np.empty((0, GENES))
        seeds = np.asarray(seeds, dtype=np.int64).reshape(-1)
        if seeds.shape != (len(genomes),):
            raise ValueError(f'need one seed per genome: {len(genomes)} genomes, '
                             f'{seeds.size} seeds')
        if ((seeds < 0) | (seeds >= protocol.MAX_SEED)).any():
            raise ValueError(f'episode seeds must be integers in [0, 2**53), got '
                             f'{seeds[(seeds < 0) | (seeds >= protocol.MAX_SEED)][0]}')
        if not len(genomes):
            return None
        genes = array.array('d', genomes.tobytes())
        reason = ''
        for attempt in range(1, self.max_retries + 2):
            episode, reason = self._attempt(genes, seeds)
            if episode is not None:
                return episode
            self.restarts += attempt <= self.max_retries
            self.node.get_logger().warning(
                f'episode of {len(seeds)} robots, attempt {attempt}/{self.max_retries + 1}: '
                f'{reason}' + ('; starting it again under a new episode id'
                               if attempt <= self.max_retries else ''))
        raise EpisodeFailed(f'an episode of {len(seeds)} robots failed '
                            f'{self.max_retries + 1} times; last: {reason}. Are the robot '
                            f'node ({self.topics[LIGHT]}) and {self.controller_node} running?')

    def _attempt(self, genes: array.array, seeds: np.ndarray) -> tuple[_Episode | None, str]:
        loaded = self._controller.set_parameters([ParameterMsg(
            name='genomes', value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE_ARRAY,
                                                 double_array_value=genes))])
        steps = self._robot_client().get_parameters(['steps'])
        for future in (loaded, steps):
            future.add_done_callback(lambda _: self._wake.set())
        if not self._wait(lambda: loaded.done() and steps.done(), self.stall_timeout_s):
            return None, (f'no answer from the parameter services of {self.controller_node} '
                          f'and {self.robot_node} within {self.stall_timeout_s} s')
        result = loaded.result().results[0]
        if not result.successful:
            raise EpisodeFailed(f'{self.controller_node} refused the genomes: {result.reason}')
        values = steps.result().values
        if not values or values[0].type != ParameterType.PARAMETER_INTEGER:
            raise EpisodeFailed(f'{self.robot_node} has no integer parameter steps: is it a '
                                'robot node?')
        episode = _Episode(next(self._ids), len(seeds), values[0].integer_value, self._observed)
        self._current = episode
        self.episodes += 1
        self._start_pub.publish(protocol.pack_episode_start(episode.episode, seeds, raw=True))
        self._wait(lambda: episode.finished, lambda: episode.progress + self.stall_timeout_s)
        self._current = None
        if episode.complete:
            return episode, ''
        return None, (f'episode {episode.episode}: ' + (episode.error or (
            f'stalled at step {episode.next_step} of {episode.steps}: no new message for '
            f'{self.stall_timeout_s} s')))

    def _observer(self, topic: str, unpack) -> Callable:
        def observe(msg) -> None:
            try:
                batch = unpack(msg)
            except protocol.Malformed as exc:
                self.dropped.add('malformed', str(exc))
                return
            episode = self._current
            if episode is not None and batch.episode == episode.episode:
                episode.add(topic, batch.step, batch.values)
                if episode.finished:
                    self._wake.set()
        return observe


def _python(value: ParameterValue):
    """A ParameterValue message as a plain Python value (for JSON)."""
    field = {ParameterType.PARAMETER_BOOL: 'bool_value',
             ParameterType.PARAMETER_INTEGER: 'integer_value',
             ParameterType.PARAMETER_DOUBLE: 'double_value',
             ParameterType.PARAMETER_STRING: 'string_value',
             ParameterType.PARAMETER_BOOL_ARRAY: 'bool_array_value',
             ParameterType.PARAMETER_INTEGER_ARRAY: 'integer_array_value',
             ParameterType.PARAMETER_DOUBLE_ARRAY: 'double_array_value',
             ParameterType.PARAMETER_STRING_ARRAY: 'string_array_value'}.get(value.type)
    if field is None:
        return None
    v = getattr(value, field)
    return v if isinstance(v, (bool, int, float, str)) else list(v)


# --- running nodes in one process ----------------------------------------------------------

@contextmanager
def spinning(nodes: list[Node], context=None, thread: bool = True,
             executor_class=SingleThreadedExecutor) -> Iterator[Executor]:
    """All nodes on one executor, spun in a background thread unless ``thread`` is False;
    on exit the executor stops and the nodes are destroyed, whatever happened."""
    executor = executor_class(context=context)
    for node in nodes:
        executor.add_node(node)
    worker = threading.Thread(target=_spin, args=(executor,), daemon=True) if thread else None
    if worker is not None:
        worker.start()
    try:
        yield executor
    finally:
        executor.shutdown()
        if worker is not None:
            worker.join(timeout=10)
        for node in nodes:
            node.destroy_node()


def events_executor(context=None) -> Executor:
    """rclpy's EventsExecutor, with a fraction of the Python executor's overhead per
    callback, where it can run (it needs a stderr with a file descriptor for its crash
    handler), else a SingleThreadedExecutor.  Spin it from the thread that creates
    entities: here, let the evaluator spin it (``thread=False``)."""
    try:
        from rclpy.experimental.events_executor import EventsExecutor
        return EventsExecutor(context=context)
    except (ImportError, ValueError, OSError):
        return SingleThreadedExecutor(context=context)


def _spin(executor: Executor) -> None:
    try:
        executor.spin()
    except ExternalShutdownException:
        pass


@dataclass
class LocalGraph:
    """simulator + controller + evolution_manager in one process, on one executor."""

    robot: Node
    controller: Node
    manager: Node
    executor: Executor

    @property
    def evaluator(self) -> GraphEvaluator:
        return self.manager.evaluator


@contextmanager
def local_graph(context=None, simulator: dict | None = None, controller: dict | None = None,
                manager: dict | None = None, cli_args: list[str] | None = None,
                namespace: str = '', thread: bool = True,
                executor_class=SingleThreadedExecutor,
                bearings: bool = True) -> Iterator[LocalGraph]:
    """Build the three nodes with these parameter dicts (and ``--ros-args`` cli_args such as
    a params file), and spin them: in a background thread, or (``thread=False``) by the
    evaluator itself whenever it waits.  ``bearings``: the manager observes the bearing
    topic too, so that ``evaluator.trace()`` works."""
    from .controller import GENOMES, Controller
    from .evolution_manager import MANAGER_SPECS, EvolutionManager
    from .params import overrides
    from .simulator import Simulator

    common = dict(context=context, cli_args=cli_args, namespace=namespace)
    nodes: list[Node] = []
    try:
        sim = Simulator(parameter_overrides=overrides(Simulator.parameter_specs(), simulator),
                        **common)
        nodes.append(sim)
        ctrl = Controller(parameter_overrides=overrides([GENOMES], controller), **common)
        nodes.append(ctrl)
        mgr = EvolutionManager(parameter_overrides=overrides(MANAGER_SPECS, manager),
                               bearings=bearings, **common)
        nodes.append(mgr)
    except BaseException:
        for node in nodes:
            node.destroy_node()
        raise
    with spinning(nodes, context, thread, executor_class) as executor:
        if not thread:
            mgr.evaluator.executor = executor
        yield LocalGraph(sim, ctrl, mgr, executor)
