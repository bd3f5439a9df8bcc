"""A robot node over an emulated world in this process: the emulator without its serial link."""
from __future__ import annotations

from ..reality.khepera_robot import InProcessRobots, KheperaRobots
from ..reality.world import EmulatedWorld
from .params import GEOMETRY, world_from
from .robot_node import RobotNode


class WorldNode(RobotNode):
    """Drives ``world``'s robots directly; the robot-node geometry parameters place the lamp
    and set the room, as a hardware bridge declares them to the emulator."""

    def __init__(self, world: EmulatedWorld, node_name: str = 'emulator', **kwargs):
        self.emulated_world = world             # make_backend needs it during __init__
        super().__init__(node_name, **kwargs)

    def make_backend(self, values):
        return KheperaRobots(InProcessRobots(self.emulated_world), world_from(values),
                             self.task)

    def apply_parameters(self, values, changed):
        super().apply_parameters(values, changed)
        if changed & set(GEOMETRY):
            self.backend.world = world_from(values)
