"""Node health on ``/diagnostics`` (diagnostic_msgs/DiagnosticArray), once a second.

Each node reports what it dropped, by kind (``Dropped``), as one
DiagnosticStatus named ``<node>: messages``: OK while nothing was dropped
since the last report, WARN otherwise.  The evolution manager adds one status
per worker pair.  ``rqt_robot_monitor`` or ``ros2 topic echo /diagnostics``
shows them.
"""
from __future__ import annotations

from typing import Callable, Iterable

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.qos import QoSProfile

TOPIC = '/diagnostics'
PERIOD_S = 1.0
OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR
Report = DiagnosticStatus | list[DiagnosticStatus]


def status(name: str, level: bytes, message: str, values: dict,
           hardware_id: str = '') -> DiagnosticStatus:
    return DiagnosticStatus(level=level, name=name, message=message, hardware_id=hardware_id,
                            values=[KeyValue(key=str(k), value=str(v))
                                    for k, v in values.items()])


class DropReport:
    """The status of drop counters (kind -> count): WARN when they grew since the last
    report."""

    def __init__(self, node: Node, counts: Callable[[], dict],
                 hardware_id: Callable[[], str] = str):
        self.node, self.counts, self.hardware_id = node, counts, hardware_id
        self._last = 0

    def __call__(self) -> DiagnosticStatus:
        counts = dict(self.counts())
        total = sum(counts.values())
        new, self._last = total - self._last, total
        level = WARN if new else OK
        message = (f'{new} message(s) dropped in the last {PERIOD_S:g} s, {total} in all'
                   if new else f'no message dropped lately ({total} in all)')
        return status(f'{self.node.get_fully_qualified_name()}: messages', level, message,
                      {'dropped': total, **counts}, self.hardware_id())


class Diagnostics:
    """Publishes the statuses the ``reports`` give, every PERIOD_S seconds."""

    def __init__(self, node: Node, reports: Iterable[Callable[[], Report]]):
        self.node, self.reports = node, list(reports)
        self.publisher = node.create_publisher(DiagnosticArray, TOPIC, QoSProfile(depth=10))
        self.timer = node.create_timer(PERIOD_S, self.publish)

    def publish(self) -> DiagnosticArray:
        msg = DiagnosticArray()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        for report in self.reports:
            made = report()
            msg.status.extend(made if isinstance(made, list) else [made])
        self.publisher.publish(msg)
        return msg
