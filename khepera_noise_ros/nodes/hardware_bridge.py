"""The hardware bridge node: a RobotNode whose robots are Kheperas on serial ports.

Same topics, parameters and protocol as the simulator (see RobotNode), so the
controller and the evolution manager run unchanged; the episode logic and the
serial protocol live in ``reality.khepera_robot``.  ``ports`` lists one serial
port per robot (the emulator's printed devices, or e.g. /dev/ttyUSB0).

It is a managed (lifecycle) node: *configure* opens every port and checks that
a Khepera answers on it, *activate* starts serving the topics, *deactivate*
ends the episode and stops the motors, *cleanup* closes the ports.  Until it is
active it drops what arrives.  ``autostart`` configures and activates it at
start, for use without a lifecycle manager.  A robot that cannot be reached
after ``retries`` fails the episode, which the robot node logs and drops; the
motors are stopped when that happens and when the node shuts down.  Serial
settings apply from the next episode: changing them closes the ports
(stopping the motors) and reopens them on demand.
"""
from __future__ import annotations

import sys
from typing import Any

from rclpy.lifecycle import LifecycleNodeMixin, LifecycleState, TransitionCallbackReturn
from rclpy.parameter import Parameter

from ..reality.khepera_robot import KheperaRobots
from ..reality.serial_link import IDENTIFY, exchange
from ..reality.serial_robots import TURN_MODES, SerialRobots
from ..reality.serial_protocol import SPEED_MAX, Wheels
from .runtime import spin_node
from .params import GEOMETRY, SEED_MAX, Spec, check_choice, task_from, world_from
from .robot_node import RobotNode
from .simulator import SIMULATOR_SPECS

SERIAL = ('ports', 'baudrate', 'timeout_s', 'retries', 'turn_mode', 'turn_speed',
          'wheel_base_mm')

BRIDGE_SPECS = tuple(s for s in SIMULATOR_SPECS if s.name in ('deg_per_power', 'seed')) + (
    Spec('ports', ['/dev/ttyUSB0'], 'Serial ports, one per robot; an episode of B robots uses '
         'the first B.', type_=Parameter.Type.STRING_ARRAY),
    Spec('baudrate', 9600, 'Serial speed, bits/s (the Khepera\'s default is 9600).',
         50, 4000000),
    Spec('timeout_s', 0.5, 'Longest wait for a reply before the command is sent again, s.',
         0.001, 60.0),
    Spec('retries', 3, 'Times a command that got no (or a garbled) reply is sent again '
         'before the episode fails.', 0, 100),
    Spec('turn_mode', 'position', 'position: turn with the position counters (G, C, H); '
         'speed: opposite wheel speeds (D) for the time the turn takes.', choices=TURN_MODES),
    Spec('turn_speed', 20, 'Wheel speed in turn_mode speed, pulses per 10 ms (8 mm/s each).',
         1, SPEED_MAX),
    Spec('wheel_base_mm', Wheels.wheel_base_mm, 'Distance between the wheels, mm: a degree '
         'of turn in place is wheel_base_mm * pi / 360 / 0.08 pulses per wheel.', 10.0, 1000.0),
    Spec('autostart', False, 'Configure and activate at start (without a lifecycle manager); '
         'false: wait in the unconfigured state for the transitions.', read_only=True),
)
SUCCESS, FAILURE = TransitionCallbackReturn.SUCCESS, TransitionCallbackReturn.FAILURE


def serial_robots(values: dict[str, Any], logger=None) -> SerialRobots:
    """The robots on the ports (nothing is opened yet); ValueError names a bad setting."""
    check_choice('turn_mode', values['turn_mode'], TURN_MODES)
    bad = [port for port in values['ports'] if not port.strip() or '\0' in port]
    if bad:
        raise ValueError(f'ports must be device paths such as /dev/ttyUSB0, got {bad[0]!r}')
    return SerialRobots(values['ports'], baudrate=values['baudrate'],
                        timeout_s=values['timeout_s'], retries=values['retries'],
                        turn_mode=values['turn_mode'], turn_speed=values['turn_speed'],
                        logger=logger)


class HardwareBridge(LifecycleNodeMixin, RobotNode):
    """Kheperas on serial ports, as a managed node; see RobotNode for the protocol."""

    EXTRA_SPECS = BRIDGE_SPECS

    def __init__(self, node_name: str = 'hardware_bridge', backend=None, **kwargs):
        self.serving = False
        self._given = backend is not None        # a backend handed in is kept (tests)
        RobotNode.__init__(self, node_name, backend=backend, **kwargs)
        LifecycleNodeMixin.__init__(self)
        if self.values['autostart'] and self.trigger_configure() == SUCCESS:
            self.trigger_activate()

    # --- lifecycle ----------------------------------------------------------------------

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Open every port and check that a Khepera answers on it."""
        if not self._given:
            self.backend.close()
            self.backend = self.make_backend(self.values)
        try:
            self.check_ports()
        except Exception as exc:            # the ports are I/O: any failure is a FAILURE
            self.get_logger().error(f'configure failed: {exc}')
            self.backend.close()
            return FAILURE
        return SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        with self._lock:
            self.serving = True
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop serving, end the episode, stop the motors."""
        with self._lock:
            self.serving = False
            if self.episode is not None:
                self.end_episode('the node was deactivated')
            self.stop_motors()
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop the motors and close the ports."""
        self.backend.close()
        return SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        with self._lock:
            self.serving = False
        self.backend.close()
        return SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.serving = False
        self.backend.close()
        return SUCCESS

    def check_ports(self) -> None:
        """Ask every robot for its version ('B'); RobotUnreachable or OSError if one does
        not answer.  A backend without serial links (handed in) has nothing to check."""
        links = getattr(getattr(self.backend, 'bodies', None), 'links', [])
        for link, (version,) in exchange({link: [IDENTIFY] for link in links}).items():
            link.identified(version)

    def stop_motors(self) -> None:
        bodies = getattr(self.backend, 'bodies', None)
        if bodies is not None:
            bodies.stop()

    # --- serving only while active --------------------------------------------------------

    def _on_episode_start(self, msg) -> None:
        if self._serving('episode_start'):
            super()._on_episode_start(msg)

    def _on_cmd_turn(self, msg) -> None:
        if self._serving('cmd_turn'):
            super()._on_cmd_turn(msg)

    def _tick(self) -> None:
        if self.serving:
            super()._tick()

    def _resend(self) -> None:
        if self.serving:
            super()._resend()

    def _serving(self, topic: str) -> bool:
        if not self.serving:
            self.dropped.add('inactive', f'{topic} arrived while the node is not active '
                             '(configure and activate it first)')
        return self.serving

    def make_backend(self, values: dict[str, Any]) -> KheperaRobots:
        return KheperaRobots(serial_robots(values, self.get_logger()), world_from(values),
                             task_from(values), Wheels(values['wheel_base_mm']))

    def check_parameters(self, values: dict[str, Any]) -> None:
        super().check_parameters(values)
        serial_robots(values)
        Wheels(values['wheel_base_mm'])

    def apply_parameters(self, values: dict[str, Any], changed: set[str]) -> None:
        super().apply_parameters(values, changed)
        if changed & set(SERIAL):
            self.backend.close()
            self.backend = self.make_backend(values)
            if self.episode is not None:
                self.end_episode('serial settings changed')
        elif changed & (set(GEOMETRY) | {'deg_per_power'}):
            self.backend.world = world_from(values)

    def realtime_episode(self, count: int) -> tuple[int, int]:
        return (self.values['seed'] + count) % (SEED_MAX + 1), len(self.values['ports'])

    def hardware_id(self) -> str:
        return ', '.join(self.values['ports'])

    def destroy_node(self) -> None:
        """Stop the motors and close the ports before the node goes."""
        self.serving = False
        self.backend.close()
        # rclpy leaves the lifecycle state machine, which holds the node, to the garbage
        # collector; end it (after its services) first, as rclcpp's teardown does
        for service in [s for s in self.services if s.srv_type.__module__.startswith(
                'lifecycle_msgs')]:
            self.destroy_service(service)
        self._state_machine.destroy_when_not_in_use()
        super().destroy_node()


def main(args=None) -> int:
    return spin_node(HardwareBridge, args)


if __name__ == '__main__':
    sys.exit(main())
