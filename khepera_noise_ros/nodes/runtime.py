"""Process wiring for nodes: a node's main(), spinning several nodes on one executor."""
from __future__ import annotations

from contextlib import contextmanager
import os
import stat
import sys
import threading
from typing import Callable, Iterator

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.task import Future


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
            # driven by spin_forever (see events_executor); it falls back to the default
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
    """Spin ``executor`` until shutdown, on a future that never completes: an
    EventsExecutor's ``spin()`` takes no message from another process in this rclpy
    build (docs/architecture.md, ``nodes/runtime.py``)."""
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


@contextmanager
def spinning(nodes: list[Node], context=None, thread: bool = True,
             executor_class=SingleThreadedExecutor) -> Iterator[Executor]:
    """All nodes on one executor, spun in a background thread unless ``thread`` is False;
    on exit the executor stops and the nodes are destroyed, whatever happened."""
    executor = executor_class(context=context)
    for node in nodes:
        executor.add_node(node)
    worker = threading.Thread(target=_spin, args=(executor,), daemon=True) if thread else None
    if worker is not None:
        worker.start()
    try:
        yield executor
    finally:
        executor.shutdown()
        if worker is not None:
            worker.join(timeout=10)
        for node in nodes:
            node.destroy_node()


def events_executor(context=None) -> Executor:
    """rclpy's EventsExecutor, with a fraction of the Python executor's overhead per
    callback, where it can run (it needs a stderr with a file descriptor for its crash
    handler), else a SingleThreadedExecutor.  Spin it from the thread that creates
    entities: here, let the evaluator spin it (``thread=False``).  Drive it with
    ``spin_once`` or ``spin_until_future_complete`` (``spin_forever``): in this
    rclpy build its ``spin()`` takes no message or service request from another
    process."""
    try:
        from rclpy.experimental.events_executor import EventsExecutor
        return EventsExecutor(context=context)
    except (ImportError, ValueError, OSError):
        return SingleThreadedExecutor(context=context)


def _spin(executor: Executor) -> None:
    try:
        executor.spin()
    except ExternalShutdownException:
        pass
