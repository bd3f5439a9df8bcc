"""Thin rclpy adapters over the core: the robot nodes, the controller, the evolution manager.

The names below are re-exported for code that imports them from the package; new code
imports them from ``runtime`` and ``dropped``.
"""
from .dropped import Dropped  # noqa: F401
from .runtime import spin_forever, spin_node  # noqa: F401
