"""One worker pair as the evaluator sees it: a robot node and a controller in a namespace.

A ``Worker`` runs at most one episode at a time without blocking (``begin``, then ``poll``
until it reports the episode done, failed or too large) and keeps its place in the pool
as a ``WorkerState``.
"""
from __future__ import annotations

import array
from collections import deque
import enum
import time
from typing import Callable

import numpy as np
from rcl_interfaces.msg import Parameter as ParameterMsg, ParameterEvent, ParameterType, \
    ParameterValue
from rclpy.node import Node
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import qos_profile_parameter_events
from rclpy.task import Future
from std_msgs.msg import Float64MultiArray, Int32, Int32MultiArray

from ..core.network import GENES
from . import protocol
from .discovery import in_namespace
from .dropped import Dropped
from .episode import Chunk, Episode, EpisodeFailed, EpisodeIds
from .protocol import BEARING, CMD_TURN, EPISODE_START, FITNESS, GENOMES, GENOMES_LOADED, \
    LIGHT
from .schedule import Cost
from .wake import Wake

FIRST_STEP_S = 0.05     # time allowed per step before a worker is measured (serial Khepera)


# poll() outcomes
DONE, FAILED, TOO_LARGE = 'done', 'failed', 'too large'


class WorkerState(enum.Enum):
    """A worker's place in the evaluator's pool."""

    JOINING = 'joining'     # known, not yet connected and answering parameter requests
    READY = 'ready'         # connected and answering: gets a share of every batch
    LOST = 'lost'           # dropped after a failure, until both its nodes answer again


class Worker:
    """The evaluator's end of one worker pair; ``name`` is its namespace."""

    def __init__(self, node: Node, namespace: str, observed: tuple[str, ...],
                 dropped: Dropped, wake: Wake, controller_node: str = '',
                 robot_node: str = ''):
        self.node, self.dropped, self._wake = node, dropped, wake
        ns = namespace.rstrip('/')
        self.topics = {n: in_namespace(ns, n) for n in (
            LIGHT, CMD_TURN, BEARING, EPISODE_START, FITNESS, GENOMES, GENOMES_LOADED)}
        self.name = node.resolve_topic_name(self.topics[LIGHT])[:-len(LIGHT) - 1] or '/'
        self.controller_node = controller_node or in_namespace(ns, 'controller')
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
        self.state = WorkerState.JOINING
        self.reason = ''                        # why it was lost
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
        self.state, self.reason, self.failures = WorkerState.LOST, reason, self.failures + 1
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
        """Back from LOST: READY at once if its robot node still listens (it has just
        answered), else JOINING."""
        self.state = WorkerState.READY if self.listening() else WorkerState.JOINING
        self.reason, self._probe = '', None

    def check_joined(self, timeout_s: float) -> bool:
        """Move between JOINING and READY (not LOST); True when it has just become READY.
        A READY worker is checked cheaply: its robot node still listens."""
        if self.state is WorkerState.LOST:
            return False
        was_ready = self.state is WorkerState.READY
        ready = was_ready and self.listening() or self.ready(timeout_s)
        self.state = WorkerState.READY if ready else WorkerState.JOINING
        return ready and not was_ready

    def record(self) -> dict:
        """For the results: who it is, what it did, its measured cost, why it left."""
        latency, per_robot = self.cost.model or (None, None)
        return {'namespace': self.name, 'robot_node': self.robot_node,
                'controller_node': self.controller_node, 'episodes': self.episodes,
                'robots': self.robots, 'failures': self.failures,
                'latency_s': latency, 'robot_steps_per_s': per_robot and 1 / per_robot,
                'dropped': self.reason if self.state is WorkerState.LOST else None}

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
