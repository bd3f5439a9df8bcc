"""The recorder's end of the lockstep topics: it drives one robot node and keeps its readings."""
from __future__ import annotations

from collections import deque
import time
from typing import Callable

import numpy as np
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray, Int32MultiArray

from ..core.khepera import SENSORS
from ..recording import Recording
from . import protocol
from .dropped import Dropped

Policy = Callable[[np.ndarray], tuple[int, int]]


class RobotUnavailable(RuntimeError):
    """The robot node is not there or does not answer."""


class Recorder:
    """Drives one robot node through the topics and keeps what it sends.

    On the wire an episode is ``session + episode``: a session number taken from the
    clock, so a robot node that ran an earlier session never mistakes a new episode
    for a repeated start of an old one.  Recordings keep the episode numbers 0, 1, ...
    """

    def __init__(self, node: Node, timeout_s: float = 5.0, pace_s: float = 0.0):
        self.node, self.protocol = node, protocol
        self.timeout_s, self.pace_s = timeout_s, pace_s
        self.dropped = Dropped(node)
        self.resent = 0                 # readings that came again (answered, kept once)
        self._start = node.create_publisher(Float64MultiArray, protocol.EPISODE_START,
                                            protocol.QOS)
        self._cmd = node.create_publisher(Int32MultiArray, protocol.CMD_TURN, protocol.QOS)
        node.create_subscription(Float64MultiArray, protocol.LIGHT, self._on_light,
                                 protocol.QOS)
        node.create_subscription(Float64MultiArray, protocol.BEARING, self._on_bearing,
                                 protocol.QOS)
        self.session = time.time_ns() // 1_000_000 % 2 ** 30     # ids stay below 2**31
        self.wire_episode: int | None = None
        self._light: dict[int, np.ndarray] = {}
        self._bearing: dict[int, float] = {}
        self._queue: deque[int] = deque()

    def _on_light(self, msg) -> None:
        batch = self.dropped.unpacked(self.protocol.unpack_light, msg)
        if batch is None:
            return
        if batch.episode != self.wire_episode:
            self.dropped.add('other_episode', f'light for episode {batch.episode}', warn=False)
            return
        if batch.values.shape[0] != 1:
            self.dropped.add('wrong_robots', f'light has {batch.values.shape[0]} robots, the '
                             f'recorder drives 1')
            return
        if batch.step in self._light:
            self.resent += 1
        else:
            self._light[batch.step] = batch.values[0].copy()
        self._queue.append(batch.step)

    def _on_bearing(self, msg) -> None:
        batch = self.dropped.unpacked(self.protocol.unpack_bearing, msg)
        if batch is None:
            return
        if batch.episode == self.wire_episode and batch.values.shape[0] == 1:
            self._bearing.setdefault(batch.step, float(batch.values[0, 0]))

    def wait_for_robot(self, executor, timeout_s: float) -> None:
        """Until the robot node subscribes to our topics and publishes light."""
        deadline = time.monotonic() + timeout_s
        while not (self._start.get_subscription_count() and self._cmd.get_subscription_count()
                   and self.node.count_publishers(self._light_topic())):
            if time.monotonic() > deadline:
                raise RobotUnavailable(f'no robot node on {self._light_topic()} within '
                                       f'{timeout_s:g} s (is it running, in this namespace and '
                                       f'ROS_DOMAIN_ID?)')
            executor.spin_once(timeout_sec=0.05)

    def _light_topic(self) -> str:
        return self.node.resolve_topic_name(self.protocol.LIGHT)

    def record_episode(self, executor, episode: int, seed: int, steps: int, policy: Policy,
                       bearing_deg: float | None = None) -> 'EpisodeLog':
        """Run one episode of ``steps`` readings; returns what came, and what never did."""
        self.wire_episode, self._light, self._bearing = self.session + episode, {}, {}
        self._queue.clear()
        start = self.protocol.pack_episode_start(
            self.wire_episode, [seed], None if bearing_deg is None else [bearing_deg])
        answers: dict[int, tuple[int, int]] = {}
        last_news = sent_start = time.monotonic()
        self._start.publish(start)
        next_due, grace = 0.0, None
        while len(answers) < steps or (len(self._bearing) < len(self._light)
                                       and time.monotonic() < grace):
            executor.spin_once(timeout_sec=0.02)
            now = time.monotonic()
            while self._queue and now >= next_due:
                step = self._queue.popleft()
                if step >= steps:
                    continue
                if step not in answers:
                    answers[step] = policy(self._light[step])
                    next_due = now + self.pace_s
                self._cmd.publish(self.protocol.pack_cmd_turn(
                    self.wire_episode, step, [answers[step][0]], [answers[step][1]]))
                last_news = now
                if len(answers) == steps and grace is None:   # bearings may trail the light
                    grace = now + min(1.0, self.timeout_s)
            if not self._light and now - sent_start > min(1.0, self.timeout_s / 3):
                self._start.publish(start)        # the robot ignores a repeated start
                sent_start = now
            if now - last_news > self.timeout_s:
                break
        return EpisodeLog(episode, dict(self._light), dict(self._bearing), answers,
                          [s for s in range(steps) if s not in self._light])


class EpisodeLog:
    """One episode as recorded: readings, bearings and answers by step."""

    def __init__(self, episode, light, bearing, answers, lost):
        self.episode, self.light, self.bearing = episode, light, bearing
        self.answers, self.lost = answers, lost

    def recording(self, condition: str, manifest: dict, heading_deg: float | None,
                  acted: bool) -> Recording:
        """Rows in step order; stationary rows (not ``acted``) leave the command empty."""
        steps = sorted(self.light)
        n = len(steps)
        bearing = np.array([self.bearing.get(s, np.nan) for s in steps], np.float64)
        if heading_deg is not None:                 # the experimenter's fixed heading
            bearing = np.where(np.isnan(bearing), heading_deg, bearing)
        answers = np.array([self.answers.get(s, (np.nan, np.nan)) for s in steps],
                           np.float64).reshape(n, 2)
        empty = np.full(n, np.nan)
        return Recording(
            np.full(n, self.episode, np.int64), np.array(steps, np.int64), bearing,
            np.full(n, condition),
            np.array([self.light[s] for s in steps]).reshape(n, SENSORS),
            answers[:, 0] if acted else empty, answers[:, 1] if acted else empty, manifest)
