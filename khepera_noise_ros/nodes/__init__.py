"""Thin rclpy adapters over the core: simulator, controller, evolution_manager.

``protocol`` is the topic contract, ``robot_node`` the protocol every robot node
(simulator, hardware bridge) speaks, ``graph`` the evaluator that drives an
episode through the topics.
"""
from __future__ import annotations

from collections import Counter
import os
import stat
import sys
import time
from typing import Callable

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.task import Future

from .protocol import Malformed


def spin_node(make_node: Callable[[], Node], args=None,
              until: Callable[[Node], Future] | None = None) -> int:
    """The body of a node's main(): init, spin until Ctrl-C, SIGTERM, shutdown or
    ``until(node)`` completes, clean up.  Returns the exit status.

    A parameter the node refuses at start (from a params file, say) ends it with
    one line naming the value and status 2, not a traceback; a failed ``until``
    future gives status 1.  A callback that meets the shutdown a signal began (a
    publish on the closed context) ends the node as cleanly as the signal would.
    """
    stopped = 0 if until is None else 130
    for fd in (1, 2):                       # stdout, stderr (rcutils logs to stderr)
        never_block(fd)
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')   # unless asked
    rclpy.init(args=args)
    node = None
    try:
        node = make_node()
        if until is None:
            # rclpy's EventsExecutor costs a fraction of rclpy.spin's per callback; it is
            # driven by spin_forever (see graph.events_executor); it falls back to the default
            from .graph import events_executor
            executor = events_executor()
            executor.add_node(node)
            spin_forever(executor)
            return 0
        future = until(node)
        rclpy.spin_until_future_complete(node, future)
        return 1 if future.exception() is not None else 0
    except (KeyboardInterrupt, ExternalShutdownException):
        return stopped
    except (ValueError, ParameterException) as exc:
        if not rclpy.ok():
            return stopped
        print(f'{sys.argv[0]}: error: {exc}', file=sys.stderr)
        return 2
    except Exception:
        if rclpy.ok():
            raise
        return stopped
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


def spin_forever(executor) -> None:
    """Spin until shutdown.  rclpy's EventsExecutor takes no message from another
    process in ``spin()`` (this rclpy build); ``spin_until_future_complete`` on a future
    that never completes does, and, unlike ``spin_once``, stays in its C++ loop between
    callbacks (a worker pair reached 47-57% of the core at 1024 robots this way, 42-49%
    with ``spin_once``)."""
    idle = Future()
    while rclpy.ok():
        executor.spin_until_future_complete(idle, timeout_sec=1.0)


def never_block(fd: int) -> None:
    """Make writes to ``fd`` (a pipe or terminal) fail rather than wait when its reader
    stops reading: a log line is lost instead of the node freezing in write(), where no
    signal can stop it.  ``fd`` is reopened as an open file description of its own, so
    the processes sharing the pipe or terminal keep blocking writes."""
    try:
        mode = os.fstat(fd).st_mode
        if not (stat.S_ISFIFO(mode) or stat.S_ISCHR(mode)):
            return
        own = os.open(f'/proc/self/fd/{fd}', os.O_WRONLY | os.O_NONBLOCK | os.O_NOCTTY)
    except OSError:                 # no /proc, a socket, a pipe nobody reads: leave it
        return
    os.dup2(own, fd)
    os.close(own)


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
