"""The paper's 6-2-2 feed-forward controller and its genome of 20 genes.

Genome layout (the order the appendix lists them):
  genes[0:12]   input-to-hidden weights, gene 2*i + j joins input i to hidden j
  genes[12:16]  hidden-to-output weights, gene 12 + 2*j + k joins hidden j to output k
  genes[16:18]  hidden biases
  genes[18:20]  output biases
Units are logistic.  Output 0 < 0.5 turns left (-1), else right (+1); output 1
gives the power trunc(10 * out), at most 9.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from .khepera import DARK, FRONT, SENSORS

INPUTS, HIDDEN, OUTPUTS = FRONT, 2, 2
GENES = INPUTS * HIDDEN + HIDDEN * OUTPUTS + HIDDEN + OUTPUTS   # 20
LEFT, RIGHT = -1, 1
MAX_GENE = 1e30              # larger genes overflow the float32 sums


@dataclass(frozen=True)
class Weights:
    """A batch of networks, robot index last so each sum runs over contiguous arrays."""

    w_ih: np.ndarray   # (INPUTS, HIDDEN, B)
    w_ho: np.ndarray   # (HIDDEN, OUTPUTS, B)
    b_h: np.ndarray    # (HIDDEN, B)
    b_o: np.ndarray    # (OUTPUTS, B)
    _w_reading: np.ndarray = field(init=False, repr=False, compare=False)
    _b_reading: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # sum_i (1 - s_i/525) w_ij + b_j = sum_i s_i (-w_ij/525) + (b_j + sum_i w_ij):
        # folding the input scaling into the weights saves two passes per step.
        object.__setattr__(self, '_w_reading', self.w_ih * np.float32(-1.0 / DARK))
        object.__setattr__(self, '_b_reading', self.b_h + self.w_ih.sum(axis=0))


def check_genomes(genomes: npt.ArrayLike) -> np.ndarray:
    """Checked genomes.

    Args:
        genomes: (B, 20) or one (20,) genome.

    Returns:
        (B, 20) float64 genomes.

    Raises:
        ValueError: a wrong shape, or a gene that is not finite or beyond +-MAX_GENE.
    """
    g = np.asarray(genomes, dtype=np.float64)
    if g.ndim == 1:
        g = g[None, :]
    if g.ndim != 2 or g.shape[1] != GENES:
        raise ValueError(f'a genome has {GENES} genes; got an array of shape '
                         f'{np.shape(genomes)}')
    if not np.abs(g).max(initial=0.0) <= MAX_GENE:      # NaN fails too: max keeps NaN
        bad = np.argwhere(~(np.abs(g) <= MAX_GENE))[0]
        raise ValueError(f'genome {bad[0]} gene {bad[1]} is {g[tuple(bad)]}; genes must be '
                         f'finite and within +-{MAX_GENE:g} (the network runs in float32)')
    return g


def unpack(genomes: npt.ArrayLike) -> Weights:
    """The networks of (B, 20) genomes (checked), in float32, robot index last."""
    g = check_genomes(genomes).astype(np.float32).T          # (20, B)
    n_ih = INPUTS * HIDDEN
    n_ho = HIDDEN * OUTPUTS
    return Weights(
        w_ih=np.ascontiguousarray(g[:n_ih].reshape(INPUTS, HIDDEN, -1)),
        w_ho=np.ascontiguousarray(g[n_ih:n_ih + n_ho].reshape(HIDDEN, OUTPUTS, -1)),
        b_h=np.ascontiguousarray(g[n_ih + n_ho:n_ih + n_ho + HIDDEN]),
        b_o=np.ascontiguousarray(g[n_ih + n_ho + HIDDEN:]))


def pack(w: Weights) -> np.ndarray:
    """The inverse of ``unpack``: (B, 20) genomes."""
    b = w.b_o.shape[-1]
    genomes: np.ndarray = np.concatenate([w.w_ih.reshape(-1, b), w.w_ho.reshape(-1, b), w.b_h,
                                          w.b_o]).T
    return genomes


def inputs(readings: np.ndarray) -> np.ndarray:
    """The paper's input(n) = 1 - sensor(n)/525 for the front six sensors.

    Args:
        readings: (B, SENSORS or FRONT) readings.

    Returns:
        (B, FRONT) inputs.
    """
    x: np.ndarray = 1.0 - readings[:, :FRONT] * np.float32(1.0 / DARK)
    return x


def _logistic(z: np.ndarray) -> np.ndarray:
    """In-place logistic; exp overflow for very negative z correctly gives 0."""
    with np.errstate(over='ignore'):
        np.exp(np.negative(z, out=z), out=z)
    z += 1
    out: np.ndarray = np.divide(1, z, out=z)    # the same quotient; numpy vectorises divide only
    return out


def outputs(w: Weights, readings: np.ndarray) -> np.ndarray:
    """The output units' activations.

    Args:
        w: B networks.
        readings: (B, SENSORS or FRONT) float32 readings.

    Returns:
        (B, OUTPUTS) activations in (0, 1).
    """
    activations: np.ndarray = _logistic(_output_net(w, readings)).T
    return activations


def _output_net(w: Weights, readings: np.ndarray) -> np.ndarray:
    if readings.ndim != 2 or readings.shape[1] < FRONT:
        # einsum would broadcast an (8, 1) column silently into 8 one-sensor robots
        raise ValueError(f'readings must be (B, {SENSORS}) or (B, {FRONT}), batch first; '
                         f'got shape {readings.shape}')
    hidden = np.einsum('bi,ijb->jb', readings[:, :FRONT], w._w_reading)
    hidden += w._b_reading
    net: np.ndarray = np.einsum('jb,jkb->kb', _logistic(hidden), w.w_ho)
    net += w.b_o
    return net


def act(w: Weights, readings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The networks' turn commands.

    Args:
        w: B networks (``unpack``).
        readings: (B, SENSORS or FRONT) float32 readings, 0 brightest .. 525 darkest.

    Returns:
        (direction, power): int32 arrays of shape (B,), direction -1 (left) or +1 (right),
        power 0..9.
    """
    net = _output_net(w, readings)
    # logistic(net) < 0.5 exactly when net < 0: the direction needs no exp.  RIGHT - 2 *
    # (net < 0) in three cheap passes: np.where with two scalars costs more than all three.
    direction = np.less(net[0], 0).astype(np.int32)
    direction *= LEFT - RIGHT
    direction += RIGHT
    power = _logistic(net[1])
    power *= 10
    power = power.astype(np.int32)
    return direction, np.minimum(power, 9, out=power)
