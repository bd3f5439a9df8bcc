"""A client for another node's parameters that puts back what it changed."""
from __future__ import annotations

from rclpy.node import Node
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient

from .recorder import RobotUnavailable


class RobotParameters:
    """Get and set a robot node's parameters through its services, and put them back after."""

    def __init__(self, node: Node, executor, robot: str, timeout_s: float):
        self.executor, self.robot, self.timeout_s = executor, robot, timeout_s
        self.original: dict = {}
        self.client = AsyncParameterClient(node, robot)
        if not self.client.wait_for_services(timeout_sec=timeout_s):
            raise RobotUnavailable(f'robot node {robot} offers no parameter services within '
                                   f'{timeout_s:g} s')

    def _wait(self, future):
        self.executor.spin_until_future_complete(future, timeout_sec=self.timeout_s)
        if not future.done() or future.result() is None:
            raise RobotUnavailable(f'robot node {self.robot} did not answer a parameter '
                                   f'request')
        return future.result()

    def set(self, values: dict) -> None:
        first = [k for k in values if k not in self.original]
        if first:
            self.original.update(self.get(first))
        params = [Parameter(k, value=float(v) if isinstance(v, float) else v)
                  for k, v in values.items()]
        results = self._wait(self.client.set_parameters(params)).results
        refused = [f'{p.name}: {r.reason}' for p, r in zip(params, results) if not r.successful]
        if refused:
            raise ValueError(f'robot node {self.robot} refused ' + '; '.join(refused))

    def restore(self) -> None:
        """The values the robot node had before this session changed them."""
        if self.original:
            self.set(self.original)

    def get(self, names: list[str]) -> dict:
        values = self._wait(self.client.get_parameters(names)).values
        return {n: parameter_value_to_python(v) for n, v in zip(names, values)
                if v.type != 0}
