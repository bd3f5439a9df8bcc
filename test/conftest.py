"""Suite-wide set-up: DDS stays on this machine, each pytest-xdist worker gets its own block
of ROS domains and each test that asks a fresh domain (khepera_noise_ros.testing.domains)."""
import os
import signal

# Must be set before rclpy loads: Fast DDS otherwise multicasts off this machine.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
# One BLAS thread per process, set before numpy loads: the xdist workers already use every
# core, and OpenBLAS threads spinning on a shared machine made a gap test 4.5x slower (72 s
# against 16 s).  The tests' subprocesses inherit it.
for _name in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_name, '1')

# A suite started in the background by a shell without job control inherits SIGINT ignored,
# and so would every command it starts: the signal tests send them SIGINT.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

from khepera_noise_ros.testing import domains  # noqa: E402 (imports no rclpy)

domains.claim()

import pytest  # noqa: E402

from khepera_noise_ros.testing.domains import ros_domain  # noqa: E402


@pytest.fixture
def ros_context():
    """An rclpy Context on a fresh domain of this worker's, shut down after the test."""
    with ros_domain() as context:
        yield context
