"""A worker pair in one process: a robot node and its controller on one executor.

An evolution manager with several ``workers`` drives one such pair per
namespace (see docs/distributed.md), on this machine or on others in the same
ROS domain:

    python -m khepera_noise_ros.nodes.worker_pair --ros-args -r __ns:=/w0 \\
        --params-file config/sim_comb5.yaml
    python -m khepera_noise_ros.nodes.worker_pair --bridge --ros-args -r __ns:=/khepera \\
        -p "ports:=[/dev/ttyUSB0]"

The robot node is a simulator, or with ``--bridge`` a hardware bridge; both
are the ordinary nodes with their ordinary parameters.  Two choices make a pair
about twice as fast as the two nodes in processes of their own (see
docs/distributed.md): the light -> controller -> cmd_turn round trip of every
step stays inside the process, and the executor is rclpy's EventsExecutor,
which costs a fraction of the SingleThreadedExecutor per callback.  It is
driven by ``spin_forever``: in this rclpy build its ``spin()`` takes no message
or service request from another process.  Discovery
stays on this machine unless ROS_AUTOMATIC_DISCOVERY_RANGE (or
ROS_STATIC_PEERS) says otherwise.
"""
from __future__ import annotations

import functools
import os
import sys

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.parameter import Parameter
from rclpy.utilities import remove_ros_args

from .. import lifeline
from .controller import Controller
from .runtime import events_executor, spin_forever, spinning

USAGE = 'usage: worker_pair [--bridge] [--ros-args ...]'


def robot_class(argv: list[str]):
    """Simulator, or HardwareBridge with --bridge; ValueError for anything else."""
    extra = remove_ros_args(argv)[1:]
    if extra not in ([], ['--bridge']):
        raise ValueError(f'unknown argument(s) {extra}; {USAGE}')
    if extra:
        from .hardware_bridge import HardwareBridge     # serving at once, as a simulator
        return functools.partial(HardwareBridge, parameter_overrides=[
            Parameter('autostart', value=True)])
    from .simulator import Simulator
    return Simulator


def main(args=None) -> int:
    argv = sys.argv if args is None else args
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')   # unless asked
    lifeline.from_environment()         # started by a parent that may die: end with it
    nodes = []
    try:
        robot = robot_class(argv)
        rclpy.init(args=argv)
        nodes.append(robot())
        nodes.append(Controller())
        with spinning(nodes, thread=False, executor_class=events_executor) as executor:
            nodes = []                          # spinning destroys them
            spin_forever(executor)
    except (ValueError, ParameterException) as exc:
        print(f'worker_pair: error: {exc}', file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
