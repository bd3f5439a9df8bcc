"""One worker pair as the evaluator sees it: a robot node and a controller in a namespace.

A ``Worker`` runs at most one episode at a time, without blocking: ``begin``
loads a chunk's genomes into the controller (on its ``genomes`` topic, tagged
with the episode id, and waits for ``genomes_loaded``; through the
``genomes`` parameter for a controller that has no such topic) and reads the
robot node's ``steps`` (and ``ports``, the robots a hardware bridge has) when
it has not yet, or they may have changed: a ``/parameter_events`` message of
the robot node naming either, or a failed episode, has it read them again;
``poll`` then publishes ``episode_start`` and reports the episode done,
failed (stalled, or broke the protocol) or too large for the robot node.
The episode is done when the robot node's ``fitness`` message for it arrives:
one message per episode, so that a manager on another machine is not flooded
with two per step.  When the evaluator traces, the worker also observes
light, cmd_turn and bearing at every step, and checks that the fitness the
robot node reports is the one those messages give.  Messages tagged with
another episode id are ignored, so a late answer from an earlier attempt can
never be paired with the current one.

``discover`` finds worker namespaces in the ROS graph: wherever some node
publishes ``<ns>/light`` and some node subscribes to ``<ns>/episode_start``.
"""
from __future__ import annotations

import array
from collections import deque
from dataclasses import dataclass
from fnmatch import fnmatchcase
import secrets
import threading
import time
from typing import Callable, Iterable

import numpy as np
from rcl_interfaces.msg import Parameter as ParameterMsg, ParameterEvent, ParameterType, \
    ParameterValue
from rclpy.node import Node
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import qos_profile_parameter_events
from rclpy.task import Future
from std_msgs.msg import Float64MultiArray, Int32, Int32MultiArray

from ..core.khepera import SENSORS
from ..core.network import GENES
from ..core.task import step_fitness
from . import protocol
from .dropped import Dropped
from .schedule import Cost
from .protocol import BEARING, CMD_TURN, EPISODE_START, FITNESS, GENOMES, GENOMES_LOADED, \
    LIGHT

LIGHT_TYPE = 'std_msgs/msg/Float64MultiArray'
FIRST_STEP_S = 0.05     # time allowed per step before a worker is measured (serial Khepera)


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


class Episode:
    """What the evaluator has observed of one episode; filled by the subscription callbacks.

    ``topics``: the per-step topics observed (none unless tracing).  Each one's values go
    straight into a preallocated (steps, B, columns) array, in the dtype the core computes
    with (readings float32), so that nothing is stacked at the end.
    """

    LAYOUT = {LIGHT: (SENSORS, np.float32), CMD_TURN: (2, np.int32), BEARING: (1, np.float64)}

    def __init__(self, episode: int, robots: int, steps: int, topics: tuple[str, ...]):
        self.episode, self.robots, self.steps = episode, robots, steps
        self.values = {t: np.empty((steps, robots, self.LAYOUT[t][0]), self.LAYOUT[t][1])
                       for t in topics}
        self.seen = {t: np.zeros(steps, bool) for t in topics}
        self.score: np.ndarray | None = None       # the robot node's fitness, (B,)
        self.error: str | None = None
        self.complete = False
        self.progress = time.monotonic()
        self._count = 0

    @property
    def finished(self) -> bool:
        return self.complete or self.error is not None

    @property
    def next_step(self) -> int:
        """The first step some observed message is still missing for."""
        return min((int(np.argmin(seen)) if not seen.all() else self.steps
                    for seen in self.seen.values()), default=0)

    def fitness(self) -> np.ndarray:
        return self.score

    def add_fitness(self, steps: int, values: np.ndarray) -> None:
        if self.finished:
            return
        score = values[:, 0]
        if steps != self.steps:
            self.error = (f'fitness after {steps} steps, but the robot node has steps = '
                          f'{self.steps} (was it changed during the episode?)')
        elif score.shape[0] != self.robots:
            self.error = (f'fitness for episode {self.episode} has {score.shape[0]} robots, '
                          f'the episode has {self.robots}')
        elif self.score is None:
            self.score = score.copy()
            self.progress = time.monotonic()
            self._check_complete()
        elif not np.array_equal(self.score, score):
            self.error = (f'two different fitness messages for episode {self.episode}: two '
                          'robot nodes in one namespace?')

    def _check_complete(self) -> None:
        """Complete once the fitness and every observed step are in; then the fitness
        must be the one the observed readings and commands give."""
        if self.score is None or self._count < len(self.values) * self.steps:
            return
        if LIGHT in self.values and CMD_TURN in self.values:
            observed = episode_fitness(self.values[LIGHT], self.values[CMD_TURN][..., 1])
            if not np.array_equal(observed, self.score):
                robot = int(np.flatnonzero(observed != self.score)[0])
                self.error = (f'the robot node reports fitness {self.score[robot]} for robot '
                              f'{robot} of episode {self.episode}, its light and cmd_turn '
                              f'messages give {observed[robot]}')
                return
        self.complete = True

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
            self._check_complete()
        elif not np.array_equal(self.values[topic][step],
                                values.astype(self.values[topic].dtype)):
            self.error = (f'two different {topic} messages for ({self.episode}, {step}): '
                          'a node answered twice with different data')


@dataclass
class Chunk:
    """Robots [lo, hi) of a batch, and how many times an episode of them failed."""

    lo: int
    hi: int
    attempts: int = 0

    @property
    def robots(self) -> int:
        return self.hi - self.lo


# poll() outcomes
DONE, FAILED, TOO_LARGE = 'done', 'failed', 'too large'


def _in(ns: str, name: str) -> str:
    return f'{ns}/{name}' if ns else name


def is_pattern(namespace: str) -> bool:
    return any(c in namespace for c in '*?[')


def discover(node: Node, patterns: Iterable[str]) -> list[str]:
    """Namespaces matching ``patterns`` (fnmatch) where a node publishes light and a node
    subscribes to episode_start."""
    found = []
    for name, types in node.get_topic_names_and_types():
        if not name.endswith('/' + LIGHT) or LIGHT_TYPE not in types:
            continue
        ns = name[:-len(LIGHT) - 1]
        if any(fnmatchcase(ns or '/', p) for p in patterns) and node.count_publishers(name) \
                and node.count_subscribers(f'{ns}/{EPISODE_START}'):
            found.append(ns or '/')
    return sorted(found)


class Wake:
    """What the callbacks set when there is news for the evaluator: an Event for a waiter
    in another thread, and the Future of a wait that spins the executor itself."""

    def __init__(self):
        self._event = threading.Event()
        self._future: Future | None = None

    def set(self) -> None:
        self._event.set()
        future = self._future
        if future is not None and not future.done():
            future.set_result(True)

    def arm(self) -> Future:
        """A Future that the next ``set`` completes."""
        self._future = Future()
        return self._future

    def wait(self, timeout_s: float) -> None:
        self._event.wait(timeout_s)

    def clear(self) -> None:
        self._event.clear()


class Worker:
    """The evaluator's end of one worker pair; ``name`` is its namespace."""

    def __init__(self, node: Node, namespace: str, observed: tuple[str, ...],
                 dropped: Dropped, wake: Wake, controller_node: str = '',
                 robot_node: str = ''):
        self.node, self.dropped, self._wake = node, dropped, wake
        ns = namespace.rstrip('/')
        self.topics = {n: _in(ns, n) for n in (LIGHT, CMD_TURN, BEARING, EPISODE_START,
                                               FITNESS, GENOMES, GENOMES_LOADED)}
        self.name = node.resolve_topic_name(self.topics[LIGHT])[:-len(LIGHT) - 1] or '/'
        self.controller_node = controller_node or _in(ns, 'controller')
        self.robot_node = robot_node
        self._controller = AsyncParameterClient(node, self.controller_node)
        self._robot: AsyncParameterClient | None = None
        self._start_pub = node.create_publisher(Float64MultiArray, self.topics[EPISODE_START],
                                                protocol.QOS)
        self._genomes_pub = node.create_publisher(Float64MultiArray, self.topics[GENOMES],
                                                  protocol.QOS)
        node.create_subscription(Int32, self.topics[GENOMES_LOADED], self._on_loaded,
                                 protocol.QOS)
        node.create_subscription(ParameterEvent, '/parameter_events', self._on_parameters,
                                 qos_profile_parameter_events)
        unpack = {LIGHT: (Float64MultiArray, protocol.unpack_light),
                  CMD_TURN: (Int32MultiArray, protocol.unpack_cmd_turn),
                  BEARING: (Float64MultiArray, protocol.unpack_bearing),
                  FITNESS: (Float64MultiArray, protocol.unpack_fitness)}
        self.observed = observed
        for topic in (*observed, FITNESS):
            msg_type, unpacker = unpack[topic]
            node.create_subscription(msg_type, self.topics[topic],
                                     self._observer(topic, unpacker), protocol.QOS, raw=True)
        self.alive, self.joined, self.reason = True, False, ''
        self.queue: deque[Chunk] = deque()
        self.chunk: Chunk | None = None
        self.episode: Episode | None = None
        self.cost = Cost()                      # seconds per step, by robots
        self.capacity: int | None = None        # robots per episode (ports); None: any
        self.episodes = self.robots = self.failures = 0
        self._requests: tuple | None = None
        # the robot node's steps, read with its ports; kept until one of its parameter events
        # names either, or an episode fails (a failure may be a stale value)
        self._steps: int | None = None
        self._id = 0                            # of the episode being loaded or run
        self._genomes = np.empty((0, GENES))
        self._ack: Future | None = None         # genomes_loaded for self._id
        self._began = 0.0
        self._probe: tuple[float, list] | None = None

    # --- the graph ------------------------------------------------------------------------

    def missing(self) -> list[str]:
        """What this pair still lacks in the ROS graph (empty: connected)."""
        node, t = self.node, self.topics
        missing = []
        if self._start_pub.get_subscription_count() < 1:
            missing.append(f'a robot node subscribed to {t[EPISODE_START]}')
        mine = 1 if self.observed else 0        # this evaluator's own subscriptions
        if node.count_publishers(t[LIGHT]) < 1 or node.count_publishers(t[FITNESS]) < 1 \
                or node.count_subscribers(t[CMD_TURN]) < 1 + mine:
            missing.append(f'a robot node publishing {t[LIGHT]} and {t[FITNESS]} and '
                           f'subscribed to {t[CMD_TURN]}')
        if node.count_publishers(t[CMD_TURN]) < 1 \
                or node.count_subscribers(t[LIGHT]) < 1 + mine:
            missing.append(f'a controller publishing {t[CMD_TURN]} and subscribed to '
                           f'{t[LIGHT]}')
        if not self._controller.services_are_ready():
            missing.append(f'the parameter services of {self.controller_node}')
        return missing

    def ready(self, timeout_s: float = 2.0) -> bool:
        """Connected, and both nodes have answered a parameter request: a service that
        discovery shows may still take long over its first request (over a second, on
        a busy machine), which would fail a first episode.  Sends the request when none
        is pending (again after ``timeout_s``)."""
        robot = self.robot_client()
        return not self.missing() and robot is not None and robot.services_are_ready() \
            and self.answers(timeout_s)

    def listening(self) -> bool:
        """Does some robot node still subscribe to episode_start (one cheap check)?"""
        return self._start_pub.get_subscription_count() > 0

    def robot_names(self) -> list[str]:
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

    def robot_client(self) -> AsyncParameterClient | None:
        """The robot node's parameter client, its name found from who publishes light;
        None while no such node is known.  EpisodeFailed if there are several."""
        if self._robot is None:
            if not self.robot_node:
                names = self.robot_names()
                if len(names) > 1:
                    raise EpisodeFailed(f'expected one robot node (publishing '
                                        f'{self.topics[LIGHT]}, subscribed to '
                                        f'{self.topics[EPISODE_START]}), found {names}; name '
                                        'it with robot_node')
                if not names:
                    return None
                self.robot_node = names[0]
            self._robot = AsyncParameterClient(self.node, self.robot_node)
        return self._robot

    # --- one episode ----------------------------------------------------------------------

    @property
    def busy(self) -> bool:
        return self.chunk is not None

    def begin(self, chunk: Chunk, genomes: np.ndarray, ids: EpisodeIds) -> None:
        """Start loading ``chunk`` (its genomes: the batch's rows lo..hi) for a new
        episode id."""
        self.chunk, self.episode, self._requests = chunk, None, None
        self._id, self._genomes = next(ids), genomes[chunk.lo:chunk.hi]
        self._began = time.monotonic()
        self._send()

    def _send(self) -> None:
        robot = self.robot_client()
        if robot is None:
            return
        # the topic when the controller both takes genomes and (as this node has
        # discovered) acknowledges them: an ack to a reader not yet matched would be lost
        if self._genomes_pub.get_subscription_count() \
                and self.node.count_publishers(self.topics[GENOMES_LOADED]):
            self._ack = loaded = Future()
            self._genomes_pub.publish(protocol.pack_genomes(self._id, self._genomes, raw=True))
        else:                       # a controller with the parameter only
            loaded = self._controller.set_parameters([ParameterMsg(
                name='genomes', value=ParameterValue(
                    type=ParameterType.PARAMETER_DOUBLE_ARRAY,
                    double_array_value=array.array('d', np.ascontiguousarray(
                        self._genomes, np.float64).tobytes())))])
        # two requests: one naming a parameter the node lacks (ports) returns no values
        self._requests = (loaded,) if self._steps is not None else (
            loaded, robot.get_parameters(['steps']), robot.get_parameters(['ports']))
        for future in self._requests:
            future.add_done_callback(lambda _: self._wake.set())

    def _on_parameters(self, event: ParameterEvent) -> None:
        if event.node == self.robot_node and any(
                p.name in ('steps', 'ports') for p in (
                    *event.new_parameters, *event.changed_parameters, *event.deleted_parameters)):
            self._steps = None

    def _on_loaded(self, msg: Int32) -> None:
        ack = self._ack
        if ack is not None and msg.data == self._id and not ack.done():
            ack.set_result(True)

    def poll(self, seeds: np.ndarray, stall_timeout_s: float) -> tuple[str, str] | None:
        """Advance the current chunk: None while it runs, else (DONE, ''),
        (FAILED, reason) or (TOO_LARGE, '') once ``capacity`` is known to be smaller."""
        now = time.monotonic()
        if self.episode is not None:
            return self._running(now, stall_timeout_s)
        if self._requests is None:
            self._send()
        if self._requests is None or not all(f.done() for f in self._requests):
            if now - self._began < stall_timeout_s:
                return None
            return self._fail(f'no answer within {stall_timeout_s} s from {self._awaited()}')
        steps = self._loaded()
        if self.capacity is not None and self.chunk.robots > self.capacity:
            return TOO_LARGE, ''
        self.episode = Episode(self._id, self.chunk.robots, steps, self.observed)
        self.episodes += 1
        self._start_pub.publish(protocol.pack_episode_start(
            self.episode.episode, seeds[self.chunk.lo:self.chunk.hi], raw=True))
        return None

    def _awaited(self) -> str:
        """Who has not answered the loading requests yet."""
        robot = f'the parameter services of {self.robot_node or "a robot node"}'
        if self._requests is None:
            return robot
        loaded, *reads = self._requests
        awaited = [] if loaded.done() else [
            f'{self.controller_node} ({self.topics[GENOMES_LOADED]} for episode {self._id})'
            if loaded is self._ack else f'the parameter services of {self.controller_node}']
        return ' and '.join(awaited + ([] if all(f.done() for f in reads) else [robot]))

    def _loaded(self) -> int:
        """The robot node's steps, once the genomes are in; learns its capacity."""
        loaded, *reads = (f.result().values if i else f.result()
                          for i, f in enumerate(self._requests))
        if loaded is not True and not loaded.results[0].successful:
            raise EpisodeFailed(f'{self.controller_node} refused the genomes: '
                                f'{loaded.results[0].reason}')
        if not reads:
            return self._steps
        steps, ports = reads
        if not steps or steps[0].type != ParameterType.PARAMETER_INTEGER:
            raise EpisodeFailed(f'{self.robot_node} has no integer parameter steps: is it a '
                                'robot node?')
        if ports and ports[0].type == ParameterType.PARAMETER_STRING_ARRAY:
            self.capacity = max(1, len(ports[0].string_array_value))
        self._steps = steps[0].integer_value
        return self._steps

    def _running(self, now: float, stall_timeout_s: float) -> tuple[str, str] | None:
        episode = self.episode
        if episode.complete:
            self.cost.add(episode.robots, (now - self._began) / episode.steps)
            self.robots += episode.robots
            return DONE, ''
        if episode.error is not None:
            return self._fail(f'episode {episode.episode}: {episode.error}')
        allowed = self.allowance(stall_timeout_s)
        if now - episode.progress < allowed:
            return None
        if self.observed:
            return self._fail(f'episode {episode.episode} stalled at step {episode.next_step} '
                              f'of {episode.steps}: no new message for {stall_timeout_s} s')
        return self._fail(f'episode {episode.episode} stalled: no fitness within '
                          f'{allowed:.3g} s (stall_timeout_s {stall_timeout_s} + twice the '
                          f'{episode.steps} steps the worker is expected to take)')

    def _fail(self, reason: str) -> tuple[str, str]:
        self._steps = None                  # read again: a changed steps may be the cause
        return FAILED, reason

    def allowance(self, stall_timeout_s: float) -> float:
        """How long the running episode may go without news.  Observing every step, that
        is ``stall_timeout_s``; else its one message comes at the end, so add twice the
        time its steps should take at this worker's measured speed."""
        episode = self.episode
        if self.observed:
            return stall_timeout_s
        model = self.cost.model
        per_step = model[0] + model[1] * episode.robots if model else FIRST_STEP_S
        return stall_timeout_s + 2 * episode.steps * per_step

    def release(self) -> None:
        """Forget the current chunk (after it is done or failed)."""
        self.chunk, self.episode, self._requests, self._ack = None, None, None, None

    def news(self) -> bool:
        """Has something happened that poll() would act on?"""
        if self.episode is not None:
            return self.episode.finished
        return self._requests is None or all(f.done() for f in self._requests)

    def deadline(self, stall_timeout_s: float) -> float:
        if self.episode is None:
            return self._began + stall_timeout_s
        return self.episode.progress + self.allowance(stall_timeout_s)

    # --- leaving and coming back ----------------------------------------------------------

    def drop(self, reason: str) -> list[Chunk]:
        """Leave the pool; returns the chunks it held (the current one first)."""
        held = ([self.chunk] if self.chunk is not None else []) + list(self.queue)
        self.queue.clear()
        self.release()
        self.alive, self.reason, self.failures = False, reason, self.failures + 1
        self._probe = None
        return held

    def answers(self, timeout_s: float) -> bool:
        """Have both its nodes answered a parameter request since it joined or was dropped
        (for a dropped worker: it was stopped and resumed, or restarted)?  Sends a request
        when none is pending."""
        if self._probe is not None and all(f.done() for f in self._probe[1]):
            return True
        if self.missing() or (self._probe is not None
                              and time.monotonic() - self._probe[0] < timeout_s):
            return False
        robot = self.robot_client()
        if robot is not None:
            self._probe = (time.monotonic(), [robot.get_parameters(['steps']),
                                              self._controller.get_parameter_types(['genomes'])])
        return False

    def rejoin(self) -> None:
        self.alive, self.reason, self._probe = True, '', None

    def record(self) -> dict:
        """For the results: who it is, what it did, its measured cost, why it left."""
        latency, per_robot = self.cost.model or (None, None)
        return {'namespace': self.name, 'robot_node': self.robot_node,
                'controller_node': self.controller_node, 'episodes': self.episodes,
                'robots': self.robots, 'failures': self.failures,
                'latency_s': latency, 'robot_steps_per_s': per_robot and 1 / per_robot,
                'dropped': None if self.alive else self.reason}

    def _observer(self, topic: str, unpack) -> Callable:
        def observe(msg) -> None:
            batch = self.dropped.unpacked(unpack, msg)
            if batch is None:
                return
            episode = self.episode
            if episode is not None and batch.episode == episode.episode:
                if topic == FITNESS:
                    episode.add_fitness(batch.step, batch.values)
                else:
                    episode.add(topic, batch.step, batch.values)
                if episode.finished:
                    self._wake.set()
        return observe
