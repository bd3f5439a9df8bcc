"""Waking the evaluator when a callback has news for it."""
from __future__ import annotations

import threading

from rclpy.task import Future


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
