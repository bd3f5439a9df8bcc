"""ROS domains for tests: a fresh one per test, never one another test of the run or another
pytest-xdist worker holds, and offset by the run's base so that concurrent runs (each with its
own ``ROS_DOMAIN_ID``) start apart.

Each of the run's N workers owns its own block of the 232 ids (1..232: Fast DDS refuses an id
above 232, whose ports pass 65535, and 0 is every ROS user's default), shifted by the base.  The
first id of its block is the worker's home: its ``ROS_DOMAIN_ID``, for whatever a test runs in
process or starts without a domain of its own; the others are handed out in turn."""
from __future__ import annotations

from contextlib import contextmanager
import itertools
import os
from typing import TYPE_CHECKING, Iterator

if TYPE_CHECKING:
    from rclpy.context import Context

FIRST, IDS = 1, 232
BASE = 'KHEPERA_NOISE_TEST_DOMAIN_BASE'     # the run's base, inherited by its workers

_counter = itertools.count()


def worker() -> tuple[int, int]:
    """(index, count) of this pytest-xdist worker ('gw3' of 4 is (3, 4)); (0, 1) without
    xdist."""
    name = os.environ.get('PYTEST_XDIST_WORKER', 'gw0')
    count = int(os.environ.get('PYTEST_XDIST_WORKER_COUNT', '1'))
    index = int(name.removeprefix('gw'))
    if not 0 <= index < count <= IDS // 2:
        raise ValueError(f'pytest-xdist worker {name!r} of {count}: at most {IDS // 2} '
                         'workers, each with two domains or more')
    return index, count


def domain(base: int, index: int, count: int, n: int) -> int:
    """The n-th domain (n = 0 is the home) of worker ``index`` of ``count`` in a run whose base
    is ``base``: worker blocks of ``IDS // count`` ids never overlap, whatever the base."""
    size = IDS // count
    return FIRST + (base + index * size + n % size) % IDS


def run_base() -> int:
    """The base the run inherited, else the user's ROS_DOMAIN_ID, else one drawn from the run
    (shared by its workers) or the process."""
    for name in (BASE, 'ROS_DOMAIN_ID'):
        if os.environ.get(name, '').isdigit():
            return int(os.environ[name])
    run = os.environ.get('PYTEST_XDIST_TESTRUNUID')
    return int(run[:8], 16) if run else os.getpid()


def claim() -> int:
    """Settle the run's base (for the workers to inherit) and make this process's
    ROS_DOMAIN_ID its home domain; that domain.  Call before rclpy loads; calling again
    changes nothing."""
    os.environ.setdefault(BASE, str(run_base()))
    home = domain(int(os.environ[BASE]), *worker(), 0)
    os.environ['ROS_DOMAIN_ID'] = str(home)
    return home


def next_domain_id() -> int:
    """A domain for one test: none other of this run holds it while the test runs (unless it
    runs more than a block's worth of domains at once)."""
    index, count = worker()
    n = 1 + next(_counter) % (IDS // count - 1)
    return domain(int(os.environ.get(BASE, run_base())), index, count, n)


@contextmanager
def ros_domain(args: list[str] | None = None) -> Iterator['Context']:
    """A fresh rclpy Context on its own domain (with command-line ``args``, e.g. a
    ``--params-file``), always shut down."""
    import rclpy
    from rclpy.context import Context
    context = Context()
    rclpy.init(args=args, context=context, domain_id=next_domain_id())
    try:
        yield context
    finally:
        context.try_shutdown()
