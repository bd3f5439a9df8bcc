"""Counting and logging the messages a node drops."""
from __future__ import annotations

from collections import Counter
import time
from typing import Callable

from rclpy.node import Node

from .protocol import Malformed


class Dropped(Counter):
    """Messages a node dropped, by kind; each drop is logged, warnings at most once a
    second per kind (the count in the next one says how many there were)."""

    def __init__(self, node: Node):
        super().__init__()
        self._logger = node.get_logger()
        self._warned: dict[str, float] = {}

    def add(self, kind: str, reason: str, warn: bool = True) -> bool:
        """Count and log one dropped message; returns False so a check can return it."""
        self[kind] += 1
        message = f'dropped a message ({kind}, {self[kind]} so far): {reason}'
        now = time.monotonic()
        if warn and now - self._warned.get(kind, -1.0) >= 1.0:
            self._warned[kind] = now
            self._logger.warning(message)
        else:
            self._logger.debug(message)
        return False

    def unpacked(self, unpack: Callable, msg):
        """``unpack(msg)``, or None once a malformed message is counted with its reason."""
        try:
            return unpack(msg)
        except Malformed as exc:
            self.add('malformed', str(exc))
            return None
