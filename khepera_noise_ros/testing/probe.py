"""Helpers for the node tests: a probe node that plays the other end of the lockstep topics,
a listener that subscribes to a robot's sensors as a user's node would, node factories."""
from __future__ import annotations

import threading
import time
from typing import Callable

import numpy as np
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from sensor_msgs.msg import Illuminance
from std_msgs.msg import Float64, Float64MultiArray, Int32MultiArray

from khepera_noise_ros.nodes import protocol
from khepera_noise_ros.nodes.controller import GENOMES, Controller
from khepera_noise_ros.nodes.evolution_manager import MANAGER_SPECS, EvolutionManager
from khepera_noise_ros.nodes.params import overrides
from khepera_noise_ros.nodes.simulator import Simulator

TIMEOUT = 10.0


def wait_for(condition: Callable[[], bool], timeout: float = TIMEOUT) -> bool:
    """Poll ``condition`` (the nodes spin in a background thread) until true or timeout."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.002)
    return True


def simulator(context, cli_args=None, **values) -> Simulator:
    return Simulator(context=context, cli_args=cli_args,
                     parameter_overrides=overrides(Simulator.parameter_specs(), values))


def controller(context, cls=Controller, cli_args=None, **values) -> Controller:
    return cls(context=context, cli_args=cli_args,
               parameter_overrides=overrides([GENOMES], values))


def manager(context, name: str = 'evolution_manager', trace: bool = False,
            **values) -> EvolutionManager:
    values = {'results_path': '', 'ready_timeout_s': 20.0, **values}
    return EvolutionManager(name, trace=trace, context=context,
                            parameter_overrides=overrides(MANAGER_SPECS, values))


class Probe(Node):
    """Publishes on every lockstep topic and records what arrives on each."""

    def __init__(self, context):
        super().__init__('probe', context=context)
        self.received: dict[str, list] = {t: [] for t in (
            protocol.LIGHT, protocol.BEARING, protocol.CMD_TURN, protocol.FITNESS,
            'best_fitness')}
        self._lock = threading.Lock()
        self.pub = {
            protocol.EPISODE_START: self.create_publisher(
                Float64MultiArray, protocol.EPISODE_START, protocol.QOS),
            protocol.CMD_TURN: self.create_publisher(Int32MultiArray, protocol.CMD_TURN,
                                                     protocol.QOS),
            protocol.LIGHT: self.create_publisher(Float64MultiArray, protocol.LIGHT,
                                                  protocol.QOS)}
        for topic, msg_type in ((protocol.LIGHT, Float64MultiArray),
                                (protocol.BEARING, Float64MultiArray),
                                (protocol.CMD_TURN, Int32MultiArray),
                                (protocol.FITNESS, Float64MultiArray),
                                ('best_fitness', Float64)):
            self.create_subscription(msg_type, topic, self._recorder(topic), protocol.QOS)

    def _recorder(self, topic: str):
        def record(msg):
            with self._lock:
                self.received[topic].append(msg)
        return record

    def messages(self, topic: str) -> list:
        with self._lock:
            return list(self.received[topic])

    def count(self, topic: str) -> int:
        with self._lock:
            return len(self.received[topic])

    def publish(self, topic: str, msg) -> None:
        self.pub[topic].publish(msg)

    def connected(self, topic: str, subscribers: int = 1) -> bool:
        return wait_for(lambda: self.pub[topic].get_subscription_count() >= subscribers)

    def wait_light(self, episode: int, step: int, copies: int = 1) -> list[protocol.Batch]:
        """The light messages tagged (episode, step), once ``copies`` of them arrived."""
        def tagged():
            return [b for b in valid(self.messages(protocol.LIGHT), protocol.unpack_light)
                    if (b.episode, b.step) == (episode, step)]
        assert wait_for(lambda: len(tagged()) >= copies), \
            f'no light ({episode}, {step}) x{copies}; got {len(tagged())}'
        return tagged()

    def set_parameters(self, node_name: str, **values) -> list:
        """SetParameters on another node through its service; the results."""
        client = AsyncParameterClient(self, node_name)
        assert client.wait_for_services(TIMEOUT)
        future = client.set_parameters([Parameter(k, value=v) for k, v in values.items()])
        assert wait_for(future.done), f'no answer from {node_name}/set_parameters'
        return future.result().results


class Listener(Node):
    """Subscribes to light_sensor_0..7 and the lockstep light, as a user's node would."""

    def __init__(self, context, namespace: str = ''):
        super().__init__('listener', context=context, namespace=namespace)
        self.lock = threading.Lock()
        self.sensors: list[list[Illuminance]] = [[] for _ in range(8)]
        self.light: list = []
        for n in range(8):
            self.create_subscription(Illuminance, f'light_sensor_{n}',
                                     lambda msg, n=n: self._keep(self.sensors[n], msg), 10)
        self.create_subscription(Float64MultiArray, protocol.LIGHT,
                                 lambda msg: self._keep(self.light, msg), protocol.QOS)

    def _keep(self, into: list, msg) -> None:
        with self.lock:
            into.append(msg)

    def steps(self) -> dict:
        """{stamp: 8 Illuminance messages} for the steps all eight sensors arrived for."""
        with self.lock:
            by_stamp: dict = {}
            for n, messages in enumerate(self.sensors):
                for msg in messages:
                    key = (msg.header.stamp.sec, msg.header.stamp.nanosec)
                    by_stamp.setdefault(key, [None] * 8)[n] = msg
        return {k: v for k, v in by_stamp.items() if None not in v}

    def robot0_light(self) -> list[np.ndarray]:
        with self.lock:
            return [protocol.unpack_light(m).values[0] for m in self.light]


def valid(messages, unpack) -> list[protocol.Batch]:
    """The messages that keep the contract, unpacked."""
    batches = []
    for msg in messages:
        try:
            batches.append(unpack(msg))
        except protocol.Malformed:
            pass
    return batches
