"""cmd_vel (geometry_msgs/Twist, REP 103) drives a single real-time robot; bad values are
refused or clipped, counted, and the node keeps running."""
import math
import threading

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import Twist
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray

from khepera_noise_ros.nodes import protocol
from khepera_noise_ros.nodes.diagnostics import DropReport
from khepera_noise_ros.nodes.runtime import spinning
from khepera_noise_ros.testing.probe import simulator, wait_for

UNIT = math.radians(3.0) * 20.0         # rad/s of power 1 at deg_per_power 3, rate_hz 20


class Teleop(Node):
    """Publishes cmd_vel and records the robot's true lamp bearing, step by step."""

    def __init__(self, context):
        super().__init__('teleop', context=context)
        self.pub = self.create_publisher(Twist, 'cmd_vel', 10)
        self.lock = threading.Lock()
        self.bearings: list[protocol.Batch] = []
        self.create_subscription(Float64MultiArray, protocol.BEARING, self._keep, protocol.QOS)

    def _keep(self, msg) -> None:
        with self.lock:
            self.bearings.append(protocol.unpack_bearing(msg))

    def drive(self, z: float, **others) -> None:
        msg = Twist()
        msg.angular.z = z
        for name, value in others.items():
            setattr(msg.linear, name, value)
        self.pub.publish(msg)

    def turns_since(self, count: int) -> list[float]:
        """Bearing change of each step after the first ``count`` messages, degrees."""
        with self.lock:
            batches = self.bearings[count:]
        return [float((b.values[0, 0] - a.values[0, 0] + 180) % 360 - 180)
                for a, b in zip(batches, batches[1:]) if b.step == a.step + 1]

    def seen(self) -> int:
        with self.lock:
            return len(self.bearings)


def realtime_robot(context, **values):
    return simulator(context, mode='realtime', rate_hz=20.0, robots=1, steps=100000,
                     perturbation_deg=0.0, cmd_vel_timeout_s=60.0, **values)


def drive_and_watch(teleop: Teleop, z: float, steps: int = 6, **others) -> list[float]:
    """Publish cmd_vel until ``steps`` turns made after it was received are seen."""
    teleop.drive(z, **others)
    start = teleop.seen() + 2                   # one tick for the command to land
    assert wait_for(lambda: len(teleop.turns_since(start)) >= steps)
    return teleop.turns_since(start)[:steps]


def test_a_counter_clockwise_cmd_vel_turns_the_robot_left(ros_context):
    """angular.z > 0 turns the robot counter-clockwise, so the lamp's bearing (CCW
    positive in the robot frame) falls by power * deg_per_power each step."""
    sim = realtime_robot(ros_context)
    teleop = Teleop(ros_context)
    with spinning([sim, teleop], ros_context):
        assert wait_for(lambda: teleop.pub.get_subscription_count() > 0 and teleop.seen() > 2)
        assert drive_and_watch(teleop, 2 * UNIT) == [-6.0] * 6      # power 2, to the left
        assert drive_and_watch(teleop, -3 * UNIT) == [9.0] * 6      # power 3, to the right
        assert drive_and_watch(teleop, 0.0) == [0.0] * 6
    assert sum(sim.view.refused.values()) == 0


def test_bad_cmd_vel_values_are_refused_or_clipped_and_counted(ros_context):
    sim = realtime_robot(ros_context)
    teleop = Teleop(ros_context)
    with spinning([sim, teleop], ros_context):
        assert wait_for(lambda: teleop.pub.get_subscription_count() > 0 and teleop.seen() > 2)
        assert drive_and_watch(teleop, -UNIT) == [3.0] * 6
        for bad in (math.nan, math.inf, -math.inf):
            teleop.drive(bad)
        assert wait_for(lambda: sim.view.refused['refused'] == 3)
        assert drive_and_watch(teleop, -UNIT, steps=3) == [3.0] * 3     # the last good one
        assert drive_and_watch(teleop, 1000.0) == [-27.0] * 6           # clipped to power 9
        assert sim.view.refused['clipped'] == 1
        assert drive_and_watch(teleop, UNIT, x=0.2) == [-3.0] * 6       # linear: ignored
        assert sim.view.refused['ignored'] == 1
        assert sim.drop_counts()['cmd_vel_refused'] == 3
        (report,) = sim.diagnostics.publish().status          # what /diagnostics carries
        counts = {kv.key: kv.value for kv in report.values}
        assert report.name == '/simulator: messages'
        assert counts['cmd_vel_refused'] == '3' and counts['cmd_vel_clipped'] == '1'
        fresh = DropReport(sim, sim.drop_counts)          # as if no report was made yet
        assert fresh().level == DiagnosticStatus.WARN     # grew since the last report
        assert fresh().level == DiagnosticStatus.OK


def test_cmd_vel_is_refused_in_lockstep_and_for_many_robots(ros_context):
    lockstep = simulator(ros_context)
    many = simulator(ros_context, cli_args=['--ros-args', '-r', '__ns:=/many'],
                     mode='realtime', robots=3)
    teleop = Teleop(ros_context)
    to_many = teleop.create_publisher(Twist, '/many/cmd_vel', 10)
    with spinning([lockstep, many, teleop], ros_context):
        assert wait_for(lambda: teleop.pub.get_subscription_count() > 0
                        and to_many.get_subscription_count() > 0)
        teleop.drive(UNIT)
        to_many.publish(Twist())
        assert wait_for(lambda: lockstep.view.refused['refused'] == 1
                        and many.view.refused['refused'] == 1)
        assert lockstep.view.command() is None and many.view.command() is None
