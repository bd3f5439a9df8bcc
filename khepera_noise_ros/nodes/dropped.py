"""Counting and logging the messages a node drops."""
from __future__ import annotations

from collections import Counter
from typing import Callable

from rclpy.impl.rcutils_logger import RcutilsLogger
from rclpy.logging import get_logger
from rclpy.node import Node

from .protocol import Malformed


class Dropped(Counter):
    """Messages a node dropped, by kind; each drop is logged, warnings at most once a
    second per kind (the count in the next one says how many there were)."""

    def __init__(self, node: Node):
        super().__init__()
        self._logger = node.get_logger()
        # rclpy throttles per logger object and call site: one logger per kind
        self._warners: dict[str, RcutilsLogger] = {}

    def add(self, kind: str, reason: str, warn: bool = True) -> bool:
        """Count and log one dropped message; returns False so a check can return it."""
        self[kind] += 1
        message = f'dropped a message ({kind}, {self[kind]} so far): {reason}'
        warner = self._warners.get(kind) or self._warners.setdefault(
            kind, get_logger(self._logger.name))
        if not (warn and warner.warning(message, throttle_duration_sec=1.0)):
            self._logger.debug(message)
        return False

    def unpacked(self, unpack: Callable, msg):
        """``unpack(msg)``, or None once a malformed message is counted with its reason."""
        try:
            return unpack(msg)
        except Malformed as exc:
            self.add('malformed', str(exc))
            return None
