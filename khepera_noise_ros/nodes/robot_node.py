"""A robot node: the lockstep and real-time protocol of ``protocol`` over a backend.

The node only carries messages; a *backend* owns the robots.  Any object with
``reset(seed, robots=None, bearing_deg=None) -> readings (B, 8)``,
``step(direction (B,), power (B,)) -> readings (B, 8) or None when the episode
is over``, and attributes ``task`` (core Task), ``bearing_deg`` ((B,) degrees or
None when unknown) and ``done`` will do: ``core.task.Episodes`` for the
simulator, a serial link for the hardware bridge.  A subclass adds its own
parameters through ``EXTRA_SPECS``, ``check_parameters`` and
``apply_parameters``, and builds its backend in ``make_backend``.

Lockstep: ``episode_start`` resets the backend and publishes ``light`` and
``bearing`` for (episode, 0).  A ``cmd_turn`` tagged with the current
(episode, step) is applied and answered with (episode, step + 1); anything
else is counted and dropped, so a reading is never paired with another step's
command.  With no matching command after ``resend_timeout_s`` the last
messages are published again (same tags), at most ``MAX_RESENDS`` times a step.
After the last step ``fitness`` (episode, steps) gives each robot's episode
fitness, scored with ``core.task.step_fitness`` from the readings published
and the commands applied (so the same way for a simulator and a hardware
bridge), and ``bearing`` (episode, steps) marks the end; both are resent like
any step's messages until the next episode starts.  ``bearing`` is packed and
published only while some node subscribes to it (the evolution needs only
light, cmd_turn and fitness).  A
backend that fails (raises, or gives readings outside the contract) ends the
episode (``end_episode``): nothing of it is resent, and its commands are
dropped as another episode's; the node keeps running.

Real time: a timer at ``rate_hz`` steps the robots with the latest command
received for the current episode (no command: a fresh ``cmd_vel``'s turn, else
no turn), like a physical robot that does not wait.  Episodes follow one
another; ``episode_start`` still starts one with given seeds.

Beside this protocol, ``robot_view`` gives robot 0 the conventional topics
(Illuminance per sensor, sensor frames, cmd_vel), and ``diagnostics`` reports
the drop counts on /diagnostics.
"""
from __future__ import annotations

import threading
import time
from typing import Any, Protocol

import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import Float64MultiArray, Int32MultiArray

from ..core.khepera import DARK, SENSORS
from ..core.task import Task, step_fitness
from . import protocol
from .dropped import Dropped
from .diagnostics import Diagnostics, DropReport
from .params import (GEOMETRY_SPECS, TASK_SPECS, Spec, check_choice, current, declare,
                     proposed, task_from, world_from)
from .robot_view import VIEW_SPECS, RobotView

MODES = ('lockstep', 'realtime')
MAX_RESENDS = 10

ROBOT_SPECS = (
    Spec('mode', 'lockstep', 'lockstep: step when the command for the current step arrives '
         '(evolution); realtime: step on a timer at rate_hz.', choices=MODES),
    Spec('rate_hz', 10.0, 'Control steps per second in realtime mode.', 0.01, 10000.0),
    Spec('resend_timeout_s', 0.5, 'Lockstep: republish the last light and bearing when no '
         'command for the current step came within this many seconds.', 0.001, 3600.0),
) + TASK_SPECS + GEOMETRY_SPECS


class Backend(Protocol):
    task: Task
    done: bool

    @property
    def bearing_deg(self) -> np.ndarray | None: ...

    def reset(self, seed, robots: int | None = None, bearing_deg=None) -> np.ndarray: ...

    def step(self, direction, power) -> np.ndarray | None: ...


class RobotNode(Node):
    """Publishes light/bearing, applies cmd_turn, in lockstep or real time."""

    EXTRA_SPECS: tuple[Spec, ...] = ()

    def __init__(self, node_name: str = 'robot', backend: Backend | None = None, **kwargs):
        super().__init__(node_name, **kwargs)
        self.specs = self.parameter_specs()
        declare(self, self.specs)
        self.values = current(self, self.specs)
        self.check_parameters(self.values)          # a bad parameter file stops the start
        self.task = task_from(self.values)
        self.backend = backend if backend is not None else self.make_backend(self.values)
        self.dropped = Dropped(self)
        self.episode: int | None = None
        self.step_index = 0
        self._robots = 0
        self._lock = threading.RLock()
        self._last: list[tuple[Any, Any]] = []      # (publisher, msg) to resend
        self._last_sent = 0.0
        self._resends = 0
        self._pending_cmd: protocol.Batch | None = None
        self._readings: np.ndarray | None = None    # the current step's, float32
        self._score: np.ndarray | None = None       # step fitness summed so far
        self._realtime_count = 0
        self._timer = None
        self._pub_light = self.create_publisher(Float64MultiArray, protocol.LIGHT, protocol.QOS)
        self._pub_bearing = self.create_publisher(Float64MultiArray, protocol.BEARING,
                                                  protocol.QOS)
        self._pub_fitness = self.create_publisher(Float64MultiArray, protocol.FITNESS,
                                                  protocol.QOS)
        # raw: the messages arrive serialized and protocol unpacks them with numpy
        self.create_subscription(Float64MultiArray, protocol.EPISODE_START,
                                 self._on_episode_start, protocol.QOS, raw=True)
        self.create_subscription(Int32MultiArray, protocol.CMD_TURN, self._on_cmd_turn,
                                 protocol.QOS, raw=True)
        self.view = RobotView(self)
        self.diagnostics = Diagnostics(self, [DropReport(self, self.drop_counts,
                                                         self.hardware_id)])
        self.add_on_set_parameters_callback(self._on_set)
        self.add_post_set_parameters_callback(self._post_set)
        self._start_timer()

    @classmethod
    def parameter_specs(cls) -> tuple[Spec, ...]:
        return ROBOT_SPECS + VIEW_SPECS + cls.EXTRA_SPECS

    # --- hooks for subclasses -----------------------------------------------------------

    def make_backend(self, values: dict[str, Any]) -> Backend:
        raise NotImplementedError('pass backend= or override make_backend()')

    def check_parameters(self, values: dict[str, Any]) -> None:
        """Raise ValueError naming the bad value; must not change anything."""
        check_choice('mode', values['mode'], MODES)
        task_from(values)
        world_from(values)

    def apply_parameters(self, values: dict[str, Any], changed: set[str]) -> None:
        """Swap in new state; the task changes at the next episode, timing at once."""
        self.task = task_from(values)
        if changed & {'mode', 'rate_hz', 'resend_timeout_s'}:
            if 'mode' in changed and self.episode is not None:
                self.end_episode(f"mode changed to {values['mode']}")
            self._start_timer()

    def realtime_episode(self, count: int) -> tuple[int, int]:
        """(seed, robots) of the count-th episode the real-time mode starts by itself."""
        return count, 1

    def reading_noise(self):
        """The noise model the readings carry, for their variance; None: unknown."""
        return None

    def hardware_id(self) -> str:
        """What /diagnostics names as the hardware behind this node."""
        return ''

    def drop_counts(self) -> dict[str, int]:
        """Messages dropped by kind, cmd_vel refusals included (for /diagnostics)."""
        return {**self.dropped, **{f'cmd_vel_{k}': n for k, n in self.view.refused.items()}}

    def end_episode(self, reason: str, error: bool = False) -> None:
        """Forget the current episode, logging ``reason``: its last messages are not resent
        and commands for it are dropped (other_episode)."""
        message = reason if self.episode is None else f'episode {self.episode} ended: {reason}'
        (self.get_logger().error if error else self.get_logger().warning)(message)
        self.episode, self._last, self._pending_cmd = None, [], None

    # --- parameters ---------------------------------------------------------------------

    def _on_set(self, params: list[Parameter]) -> SetParametersResult:
        try:
            self.check_parameters(proposed(self, self.specs, params))
        except ValueError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _post_set(self, params: list[Parameter]) -> None:
        changed = {p.name for p in params if p.name in self.values}
        if not changed:
            return
        with self._lock:
            self.values = current(self, self.specs)
            self.apply_parameters(self.values, changed)
        self.get_logger().info('parameters set: ' + ', '.join(
            f'{n}={self.values[n]!r}' for n in sorted(changed)))

    def _start_timer(self) -> None:
        if self._timer is not None:
            self.destroy_timer(self._timer)
        realtime = self.values['mode'] == 'realtime'
        period = 1.0 / self.values['rate_hz'] if realtime else self.values['resend_timeout_s']
        self._timer = self.create_timer(period, self._tick if realtime else self._resend)

    # --- lockstep -----------------------------------------------------------------------

    def _on_episode_start(self, msg: bytes) -> None:
        start = self.dropped.unpacked(protocol.unpack_episode_start, msg)
        if start is None:
            return
        episode, seeds, bearing = start
        with self._lock:
            if episode == self.episode:
                self.dropped.add('duplicate_start', f'episode {episode} already started',
                                 warn=False)
            else:
                self._start(episode, seeds, bearing)

    def _start(self, episode: int, seeds, bearing, robots: int | None = None) -> None:
        try:
            self.backend.task = self.task
            readings = self.backend.reset(seeds, robots=robots or np.size(seeds),
                                          bearing_deg=bearing)
            _check_readings(readings)
        except Exception as exc:            # the backend is I/O: its failure ends an episode
            self.end_episode(f'episode {episode} could not start: {exc}', error=True)
            return
        self.episode, self.step_index, self._pending_cmd = episode, 0, None
        self._score = np.zeros(np.shape(readings)[0], np.float32)
        self._publish(readings)

    def _on_cmd_turn(self, msg: bytes) -> None:
        batch = self.dropped.unpacked(protocol.unpack_cmd_turn, msg)
        if batch is None:
            return
        with self._lock:
            if not self._matches(batch):
                return
            if self.values['mode'] == 'realtime':
                if self._pending_cmd is None or batch.step >= self._pending_cmd.step:
                    self._pending_cmd = batch
            else:
                self._step(batch.values)

    def _matches(self, batch: protocol.Batch) -> bool:
        """Is this command for the current episode and (in lockstep) the current step?"""
        drop = self.dropped.add
        if batch.episode != self.episode:
            return drop('other_episode', f'cmd_turn for episode {batch.episode}, current is '
                        f'{self.episode}', warn=False)
        if batch.values.shape[0] != self._robots:
            return drop('wrong_robots', f'cmd_turn has {batch.values.shape[0]} robots, '
                        f'episode {self.episode} has {self._robots}')
        if batch.step < self.step_index and (self.values['mode'] == 'lockstep'
                                             or self.backend.done):
            return drop('stale', f'cmd_turn for step {batch.step}, current step is '
                        f'{self.step_index} (a duplicate or a reply to a resend)', warn=False)
        if batch.step > self.step_index or self.backend.done:
            return drop('future', f'cmd_turn for step {batch.step} of episode {batch.episode}, '
                        f'current step is {self.step_index}')
        return True

    def _step(self, cmd: np.ndarray) -> None:
        # scored as core.task.run does: this step's readings with the command they got
        self._score += step_fitness(self._readings, cmd[:, 1])
        try:
            readings = self.backend.step(cmd[:, 0], cmd[:, 1])
            if readings is not None:
                _check_readings(readings)
        except Exception as exc:            # the backend is I/O: its failure ends an episode
            self.end_episode(f'aborted at step {self.step_index}: {exc}', error=True)
            return
        self.step_index += 1
        self._publish(readings)

    def _publish(self, readings: np.ndarray | None) -> None:
        """Bearing and light for the current step; at the end the bearing alone.  The
        bearing is packed only while someone subscribes to it."""
        episode, step = self.episode, self.step_index
        if readings is not None:
            self._robots = readings.shape[0]
            self._readings = np.asarray(readings, np.float32)
        self._last = []
        if self._pub_bearing.get_subscription_count():
            bearing = self.backend.bearing_deg
            if bearing is None:
                bearing = np.full(self._robots, np.nan)
            self._last.append((self._pub_bearing,
                               protocol.pack_bearing(episode, step, bearing, raw=True)))
        if readings is not None:
            self._last.append((self._pub_light,
                               protocol.pack_light(episode, step, readings, raw=True)))
        else:
            self._last.append((self._pub_fitness, protocol.pack_fitness(
                episode, step, self._score / np.float32(step), raw=True)))
        for pub, msg in self._last:
            pub.publish(msg)
        self._last_sent, self._resends = time.monotonic(), 0
        if readings is not None:
            self.view.publish(readings, self.reading_noise())

    def _resend(self) -> None:
        with self._lock:
            if not self._last or self._resends >= MAX_RESENDS \
                    or time.monotonic() - self._last_sent < self.values['resend_timeout_s']:
                return
            self._resends += 1
            for pub, msg in self._last:
                pub.publish(msg)
            self._last_sent = time.monotonic()
            log = self.get_logger().debug if self.backend.done else self.get_logger().warning
            log(f'no cmd_turn for episode {self.episode} step {self.step_index} within '
                f'{self.values["resend_timeout_s"]} s: published it again '
                f'({self._resends}/{MAX_RESENDS})')

    # --- real time ----------------------------------------------------------------------

    def _tick(self) -> None:
        with self._lock:
            if self.episode is None or self.backend.done:
                count = self._realtime_count
                self._realtime_count += 1
                seed, robots = self.realtime_episode(count)
                self._start(count % protocol.MAX_EPISODE, seed, None, robots)
                return
            batch, self._pending_cmd = self._pending_cmd, None
            self._step(self._idle_command() if batch is None else batch.values)

    def _idle_command(self) -> np.ndarray:
        """No cmd_turn this tick: a fresh cmd_vel's turn, else no turn."""
        command = self.view.command() if self._robots == 1 else None
        if command is not None:
            return command
        return np.column_stack([np.ones(self._robots, np.int32),
                                np.zeros(self._robots, np.int32)])


def _check_readings(readings) -> None:
    """A backend's (B, 8) readings must keep the light contract, else ValueError."""
    shape = np.shape(readings)
    if len(shape) != 2 or shape[1] != SENSORS or shape[0] < 1:
        raise ValueError(f'the backend gave readings of shape {shape}, not (robots, {SENSORS})')
    readings = np.asarray(readings)
    if not protocol.within(readings, DARK):
        raise ValueError(f'the backend gave readings outside [0, {DARK:g}] (or NaN): '
                         f'{readings.min()} .. {readings.max()}')
