"""The controller node: the 6-2-2 networks under evaluation, one per robot.

Its ``genomes`` parameter holds B genomes of 20 genes, flattened (genome 0's
genes first).  Every ``light`` message with B robots is answered at once with
the ``cmd_turn`` of the same (episode, step), computed by ``core.network.act``.
A light message with a different number of robots, or a malformed one, is
dropped and counted with a warning.

An evolution manager sends each episode's genomes on the ``genomes`` topic
instead, tagged with the episode id: the light of that episode is answered
with them, whatever the parameter holds, and each is acknowledged on
``genomes_loaded`` so that the manager starts the episode only once they are
in.  The last ``TAGGED`` episodes' networks are kept, and always those of the
episode running.  Light for an episode whose networks were pushed out by newer
ones (a flood on the topic, or more managers than ``TAGGED``) is dropped as
``forgotten``, never answered with the parameter's networks: the manager's
stall check starts that episode again with its genomes.
"""
from __future__ import annotations

import sys
from collections import deque

import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import Float64MultiArray, Int32, Int32MultiArray

from ..core import network
from . import protocol
from .dropped import Dropped
from .runtime import spin_node
from .diagnostics import Diagnostics, DropReport
from .params import Spec, declare, proposed

GENOMES = Spec('genomes', [], f'B genomes of {network.GENES} genes, flattened: one network per '
               f'robot of the episode, in the order of its seeds; genes within '
               f'+-{network.MAX_GENE:g}.',
               type_=Parameter.Type.DOUBLE_ARRAY)
TAGGED = 4          # episodes whose tagged genomes are kept (one runs at a time)
FORGOTTEN = 256     # episode ids remembered as pushed out, so their light is not misanswered


def genomes_from(value) -> np.ndarray:
    """(B, 20) genomes from the flat parameter value, or a ValueError with the reason."""
    flat = np.asarray(value, dtype=np.float64).reshape(-1)
    if flat.size % network.GENES:
        raise ValueError(f'genomes must hold a multiple of {network.GENES} values (one genome '
                         f'per robot), got {flat.size}')
    return network.check_genomes(flat.reshape(-1, network.GENES))


def _networks(weights: network.Weights | None) -> int:
    return 0 if weights is None else weights.b_o.shape[1]


class Controller(Node):
    """Answers each light message with the networks' turn commands."""

    def __init__(self, node_name: str = 'controller', **kwargs):
        super().__init__(node_name, **kwargs)
        declare(self, [GENOMES])
        self.dropped = Dropped(self)
        self.diagnostics = Diagnostics(self, [DropReport(self, lambda: dict(self.dropped))])
        self._weights = self._load(self.get_parameter(GENOMES.name).value)
        self._tagged: dict[int, network.Weights] = {}       # episode -> its networks
        self._running: int | None = None        # the episode of the last light answered
        self._forgotten: deque[int] = deque(maxlen=FORGOTTEN)
        self._pub = self.create_publisher(Int32MultiArray, protocol.CMD_TURN, protocol.QOS)
        self._pub_loaded = self.create_publisher(Int32, protocol.GENOMES_LOADED, protocol.QOS)
        self.create_subscription(Float64MultiArray, protocol.LIGHT, self._on_light,
                                 protocol.QOS, raw=True)      # unpacked by protocol, numpy
        self.create_subscription(Float64MultiArray, protocol.GENOMES, self._on_genomes,
                                 protocol.QOS, raw=True)
        self.add_on_set_parameters_callback(self._on_set)
        self.add_post_set_parameters_callback(self._post_set)

    @property
    def robots(self) -> int:
        """How many networks the genomes hold (the robots a light message must have)."""
        return _networks(self._weights)

    @staticmethod
    def _load(value) -> network.Weights | None:
        genomes = genomes_from(value)
        return network.unpack(genomes) if len(genomes) else None

    def _on_set(self, params: list[Parameter]) -> SetParametersResult:
        try:
            genomes_from(proposed(self, [GENOMES], params)[GENOMES.name])
        except ValueError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _post_set(self, params: list[Parameter]) -> None:
        """Load the value now set: with a name given twice in one request, the last."""
        if any(p.name == GENOMES.name for p in params):
            self._weights = self._load(self.get_parameter(GENOMES.name).value)

    def _on_genomes(self, msg: bytes) -> None:
        tagged = self.dropped.unpacked(protocol.unpack_genomes, msg)
        if tagged is None:
            return
        episode, genomes = tagged
        self._tagged.pop(episode, None)
        self._tagged[episode] = network.unpack(genomes)
        # forget the oldest, but never the episode running: genomes for other episodes (of
        # another manager, or a flood) must not stop it
        others = [e for e in self._tagged if e != self._running]      # oldest first
        for old in others[:max(0, len(others) - TAGGED)]:
            del self._tagged[old]
            self._forgotten.append(old)
        self._pub_loaded.publish(Int32(data=episode))

    def _on_light(self, msg: bytes) -> None:
        batch = self.dropped.unpacked(protocol.unpack_light, msg)
        if batch is None:
            return
        weights = self._tagged.get(batch.episode)
        if weights is not None:
            self._running = batch.episode
        elif batch.episode in self._forgotten:
            self.dropped.add('forgotten', f'light ({batch.episode}, {batch.step}): the genomes '
                             f'of episode {batch.episode} were pushed out by {TAGGED} newer '
                             f'sets on {protocol.GENOMES} (more managers than {TAGGED}, or a '
                             f'flood?); its manager will start it again')
            return
        else:
            weights = self._weights             # one snapshot: a set may swap it meanwhile
        robots = _networks(weights)
        if batch.values.shape[0] != robots:
            self.dropped.add('wrong_robots', f'light ({batch.episode}, {batch.step}) has '
                             f'{batch.values.shape[0]} robots, genomes hold {robots}')
            return
        readings = batch.values.astype(np.float32)      # (B, 8); sensor-major in memory
        direction, power = network.act(weights, readings)
        self._pub.publish(protocol.pack_cmd_turn(batch.episode, batch.step, direction, power,
                                                 raw=True))


def main(args=None) -> int:
    return spin_node(Controller, args)


if __name__ == '__main__':
    sys.exit(main())
