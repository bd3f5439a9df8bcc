"""Suite-wide set-up: DDS stays on loopback, and each test run gets its own domain."""
from contextlib import contextmanager
import itertools
import os

# Must be set before rclpy loads: Fast DDS otherwise multicasts off this machine.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 200))
# One BLAS thread (set before numpy loads): the analyses' matrices are small, and on a
# shared machine OpenBLAS's threads make the closed loop's regressions several times slower.
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import pytest  # noqa: E402

_domains = itertools.count()


def next_domain_id() -> int:
    """A domain for one test: distinct within this run, and from concurrent runs."""
    return (int(os.environ['ROS_DOMAIN_ID']) + next(_domains)) % 200 + 1


@contextmanager
def ros_domain(args=None):
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


@pytest.fixture
def ros_context():
    with ros_domain() as context:
        yield context
