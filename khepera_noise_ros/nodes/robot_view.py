"""The conventional per-robot view of a robot node, beside the lockstep topics.

For robot 0 of the node's batch (a ROS graph runs one robot per namespace):

- ``light_sensor_0`` .. ``light_sensor_7``: sensor_msgs/Illuminance with a stamp, the
  sensor's own frame id and the noise model's variance (``core.illuminance``).  In
  real-time mode every step is published; in lockstep mode only while someone
  subscribes, so the evolution's fast path pays nothing for it.
- ``/tf_static``: ``base_link`` to each sensor frame (``core.frames``), where
  tf2_msgs imports (a full ROS 2 install); the poses are parameters either way.
- ``cmd_vel``: geometry_msgs/Twist, angular.z in rad/s counter-clockwise positive
  (REP 103), turned into direction and power (``core.twist``) for a single robot in
  real-time mode.  It holds for ``cmd_vel_timeout_s``; a cmd_turn for the step wins.
  A value that is not finite is refused and counted, one beyond power 9 clipped and
  counted, each with a warning at most once a second.
"""
from __future__ import annotations

import math
import time
from collections import Counter

import numpy as np
from geometry_msgs.msg import Twist
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import Illuminance

from ..core.frames import BASE_FRAME, BODY_RADIUS_M, SENSOR_HEIGHT_M, sensor_poses
from ..core.illuminance import illuminance, illuminance_variance
from ..core.khepera import SENSORS
from ..core.noise import NoiseModel
from ..core.twist import Turn, turn_for
from .params import Spec

CMD_VEL = 'cmd_vel'
TF_STATIC = '/tf_static'
QOS = QoSProfile(depth=10)          # reliable, volatile: what ros2 topic and teleop use
TF_STATIC_QOS = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
WARN_EVERY_S = 1.0
LOOK_EVERY_S = 0.25         # asking the 8 publishers for subscribers costs ~30 us a step

VIEW_SPECS = (
    Spec('frame_prefix', '', "Prefix of the frame ids, e.g. 'robot1/' gives robot1/base_link "
         'and robot1/light_sensor_0.', read_only=True),
    Spec('lux_per_count', 1.0, 'Illuminance of one count: light_sensor_N carries '
         'lux_per_count * (525 - reading); 1 gives counts of brightness, not lux, until '
         'calibrated against a light meter.', 1e-9, 1e9),
    Spec('sensor_radius_m', BODY_RADIUS_M, 'Distance of each light sensor from the centre '
         'of base_link, m (sensor n faces its bearing in the Khepera numbering).',
         0.0, 10.0, read_only=True),
    Spec('sensor_height_m', SENSOR_HEIGHT_M, 'Height of the light sensors above base_link, m.',
         -10.0, 10.0, read_only=True),
    Spec('cmd_vel_timeout_s', 0.5, 'Realtime mode: a cmd_vel turns the robot for this long '
         'unless a newer one comes.', 0.0, 3600.0),
)


def static_transforms(node: Node, prefix: str, radius_m: float, height_m: float):
    """The TFMessage of the sensor frames, or None when tf2_msgs is not installed."""
    try:
        from geometry_msgs.msg import TransformStamped
        from tf2_msgs.msg import TFMessage
    except ImportError:
        return None
    stamp = node.get_clock().now().to_msg()
    transforms = []
    for pose in sensor_poses(prefix, radius_m, height_m):
        t = TransformStamped()
        t.header.stamp, t.header.frame_id, t.child_frame_id = stamp, prefix + BASE_FRAME, \
            pose.frame
        t.transform.translation.x, t.transform.translation.y = pose.x, pose.y
        t.transform.translation.z = pose.z
        (t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
         t.transform.rotation.w) = pose.quaternion
        transforms.append(t)
    return TFMessage(transforms=transforms)


class RobotView:
    """Illuminance, static frames and cmd_vel for robot 0 of ``node`` (a RobotNode)."""

    def __init__(self, node):
        self.node = node
        values = node.values
        self.frames = [p.frame for p in sensor_poses(values['frame_prefix'])]
        self.publishers = [node.create_publisher(Illuminance, f'light_sensor_{n}', QOS)
                           for n in range(SENSORS)]
        self.refused: Counter = Counter()       # cmd_vel refused or changed, by kind
        self._warned: dict[str, float] = {}
        self._turn: tuple[Turn, float] | None = None     # the latest cmd_vel, when
        self._subscribed, self._looked = False, -LOOK_EVERY_S
        self._tf = static_transforms(node, values['frame_prefix'], values['sensor_radius_m'],
                                     values['sensor_height_m'])
        if self._tf is not None:
            self._tf_pub = node.create_publisher(type(self._tf), TF_STATIC, TF_STATIC_QOS)
            self._tf_pub.publish(self._tf)
        node.create_subscription(Twist, CMD_VEL, self._on_cmd_vel, QOS)

    # --- illuminance --------------------------------------------------------------------

    def wanted(self) -> bool:
        """Publish this step?  Always in real time; in lockstep only for a subscriber
        (looked for at most every LOOK_EVERY_S, so a new one waits that long at most)."""
        if self.node.values['mode'] == 'realtime':
            return True
        now = time.monotonic()
        if now - self._looked >= LOOK_EVERY_S:
            self._looked = now
            self._subscribed = any(p.get_subscription_count() for p in self.publishers)
        return self._subscribed

    def publish(self, readings: np.ndarray, noise: NoiseModel | None) -> None:
        """Robot 0's readings of this step, (B, 8) from the backend."""
        if not self.wanted():
            return
        robot = np.asarray(readings[0], np.float64)
        lux = self.node.values['lux_per_count']
        values, variances = illuminance(robot, lux), illuminance_variance(robot, noise, lux)
        stamp = self.node.get_clock().now().to_msg()
        for pub, frame, value, variance in zip(self.publishers, self.frames, values,
                                               variances):
            msg = Illuminance(illuminance=float(value), variance=float(variance))
            msg.header.stamp, msg.header.frame_id = stamp, frame
            pub.publish(msg)

    # --- cmd_vel ------------------------------------------------------------------------

    def _warn(self, kind: str, message: str) -> None:
        """Count; warn at most once every WARN_EVERY_S per kind (the count says how many)."""
        self.refused[kind] += 1
        now = time.monotonic()
        log = self.node.get_logger()
        text = f'cmd_vel {kind} ({self.refused[kind]} so far): {message}'
        if now - self._warned.get(kind, -WARN_EVERY_S) >= WARN_EVERY_S:
            self._warned[kind] = now
            log.warning(text)
        else:
            log.debug(text)

    def _on_cmd_vel(self, msg: Twist) -> None:
        node = self.node
        values = node.values
        if values['mode'] != 'realtime':
            return self._warn('refused', 'cmd_vel drives a robot in realtime mode only; '
                              'mode is lockstep')
        robots = node.realtime_episode(0)[1]
        if robots != 1:
            return self._warn('refused', f'cmd_vel drives a single robot; this node runs '
                              f'{robots}')
        try:
            turn = turn_for(msg.angular.z, values['deg_per_power'], values['rate_hz'])
        except ValueError as exc:
            return self._warn('refused', str(exc))
        if turn.clipped:
            self._warn('clipped', f'angular.z {msg.angular.z:g} rad/s is beyond power 9 '
                       f'({9 * math.radians(values["deg_per_power"]) * values["rate_hz"]:.3g} '
                       'rad/s at this rate_hz and deg_per_power): clipped to power 9')
        others = (msg.linear.x, msg.linear.y, msg.linear.z, msg.angular.x, msg.angular.y)
        if any(others):
            self._warn('ignored', 'the Khepera turns in place here: only angular.z is used')
        self._turn = (turn, time.monotonic())

    def command(self) -> np.ndarray | None:
        """The (1, 2) cmd_turn row of a fresh cmd_vel, or None."""
        if self._turn is None:
            return None
        turn, when = self._turn
        if time.monotonic() - when > self.node.values['cmd_vel_timeout_s']:
            self._turn = None
            return None
        return np.array([[turn.direction, turn.power]], np.int32)
