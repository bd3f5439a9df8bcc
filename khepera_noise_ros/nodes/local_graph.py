"""simulator + controller + evolution_manager in one process, for scripts and tests."""
from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass
from typing import Iterator

from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.node import Node

from .controller import GENOMES, Controller
from .evolution_manager import MANAGER_SPECS, EvolutionManager
from .graph import GraphEvaluator
from .params import overrides
from .runtime import spinning
from .simulator import Simulator


@dataclass
class LocalGraph:
    """simulator + controller + evolution_manager in one process, on one executor."""

    robot: Node
    controller: Node
    manager: Node
    executor: Executor

    @property
    def evaluator(self) -> GraphEvaluator:
        return self.manager.evaluator


@contextmanager
def local_graph(context=None, simulator: dict | None = None, controller: dict | None = None,
                manager: dict | None = None, cli_args: list[str] | None = None,
                namespace: str = '', thread: bool = True,
                executor_class=SingleThreadedExecutor,
                trace: bool = True) -> Iterator[LocalGraph]:
    """Build the three nodes with these parameter dicts (and ``--ros-args`` cli_args such as
    a params file), and spin them: in a background thread, or (``thread=False``) by the
    evaluator itself whenever it waits.  ``trace``: the manager observes every step, so
    that ``evaluator.trace()`` works."""
    common = dict(context=context, cli_args=cli_args, namespace=namespace)
    nodes: list[Node] = []
    try:
        sim = Simulator(parameter_overrides=overrides(Simulator.parameter_specs(), simulator),
                        **common)
        nodes.append(sim)
        ctrl = Controller(parameter_overrides=overrides([GENOMES], controller), **common)
        nodes.append(ctrl)
        mgr = EvolutionManager(parameter_overrides=overrides(MANAGER_SPECS, manager),
                               trace=trace, **common)
        nodes.append(mgr)
    except BaseException:
        for node in nodes:
            node.destroy_node()
        raise
    with spinning(nodes, context, thread, executor_class) as executor:
        if not thread:
            mgr.evaluator.executor = executor
        yield LocalGraph(sim, ctrl, mgr, executor)
