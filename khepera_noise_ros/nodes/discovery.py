"""Finding worker pairs in the ROS graph by namespace pattern."""
from __future__ import annotations

from fnmatch import fnmatchcase
from typing import Iterable

from rclpy.node import Node

from .protocol import EPISODE_START, LIGHT

LIGHT_TYPE = 'std_msgs/msg/Float64MultiArray'


def in_namespace(ns: str, name: str) -> str:
    """``name`` in namespace ``ns`` ('' for none)."""
    return f'{ns}/{name}' if ns else name


def is_pattern(namespace: str) -> bool:
    return any(c in namespace for c in '*?[')


def discover(node: Node, patterns: Iterable[str]) -> list[str]:
    """Namespaces matching ``patterns`` (fnmatch) where a node publishes light and a node
    subscribes to episode_start."""
    found = []
    for name, types in node.get_topic_names_and_types():
        if not name.endswith('/' + LIGHT) or LIGHT_TYPE not in types:
            continue
        ns = name[:-len(LIGHT) - 1]
        if any(fnmatchcase(ns or '/', p) for p in patterns) and node.count_publishers(name) \
                and node.count_subscribers(f'{ns}/{EPISODE_START}'):
            found.append(ns or '/')
    return sorted(found)
