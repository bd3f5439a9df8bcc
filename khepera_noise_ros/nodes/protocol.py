"""The lockstep topic contract shared by every robot node, controller and manager.

Every batched message is a std_msgs MultiArray whose padding (``data_offset``)
carries a small header, so that a step's readings and commands can never be
paired across episodes or steps:

  light        Float64MultiArray  [episode, step | B x 8 readings]      robot -> controller
  cmd_turn     Int32MultiArray    [episode, step | B x (direction, power)]  controller -> robot
  bearing      Float64MultiArray  [episode, step | B x 1 lamp bearing, deg] robot (ground truth)
  episode_start Float64MultiArray [episode | B x (seed[, start bearing deg])] manager -> robot

Readings are 0 (brightest) .. 525 (darkest); direction is -1 (left) or +1
(right), power 0..9.  ``unpack_*`` raise ``Malformed`` with the reason.
"""
from __future__ import annotations

import array
from dataclasses import dataclass

import numpy as np
from std_msgs.msg import Float64MultiArray, Int32MultiArray, MultiArrayDimension

from ..core.khepera import DARK, SENSORS

LIGHT, CMD_TURN, BEARING, EPISODE_START = 'light', 'cmd_turn', 'bearing', 'episode_start'
HEADER = 2                    # episode, step
MAX_EPISODE = 2 ** 53         # episode ids and seeds must be exact in a float64


class Malformed(ValueError):
    """A message that breaks the contract; the reason names the field and value."""


@dataclass(frozen=True)
class Batch:
    episode: int
    step: int
    values: np.ndarray        # (B, columns)


def _layout(msg, robots: int, columns: int, label: str, offset: int):
    msg.layout.dim = [MultiArrayDimension(label='robots', size=robots, stride=robots * columns),
                      MultiArrayDimension(label=label, size=columns, stride=columns)]
    msg.layout.data_offset = offset
    return msg


def _pack(msg_type, typecode: str, dtype, header, values: np.ndarray, label: str):
    values = np.asarray(values)
    robots, columns = values.shape
    msg = _layout(msg_type(), robots, columns, label, len(header))
    body = np.concatenate([np.asarray(header, dtype), values.astype(dtype).ravel()])
    msg.data = array.array(typecode, body.tobytes())
    return msg


def _unpack(msg, columns: tuple[int, ...], dtype, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(header, values (B, columns)) after checking the layout against the data."""
    offset = msg.layout.data_offset
    data = np.frombuffer(msg.data, dtype=dtype) if len(msg.data) else np.empty(0, dtype)
    if len(msg.layout.dim) != 2:
        raise Malformed(f'{name}: layout must have 2 dimensions (robots, {columns[0]}), '
                        f'got {len(msg.layout.dim)}')
    robots, width = msg.layout.dim[0].size, msg.layout.dim[1].size
    if width not in columns:
        raise Malformed(f'{name}: second dimension must be one of {columns}, got {width}')
    if robots < 1 or data.size != offset + robots * width:
        raise Malformed(f'{name}: {data.size} values do not fit header {offset} + '
                        f'{robots} robots x {width}')
    return data[:offset], data[offset:].reshape(robots, width)


def _header(header: np.ndarray, name: str, size: int = HEADER) -> tuple[int, ...]:
    if header.size != size or not np.isfinite(header).all() or (header < 0).any() \
            or (header >= MAX_EPISODE).any() or (header != np.floor(header)).any():
        raise Malformed(f'{name}: header must be {size} non-negative integers, got '
                        f'{header.tolist()}')
    return tuple(int(h) for h in header)


def pack_light(episode: int, step: int, readings: np.ndarray) -> Float64MultiArray:
    """readings: (B, 8) for B robots."""
    return _pack(Float64MultiArray, 'd', np.float64, (episode, step), readings, 'sensors')


def unpack_light(msg: Float64MultiArray) -> Batch:
    header, values = _unpack(msg, (SENSORS,), np.float64, LIGHT)
    episode, step = _header(header, LIGHT)
    if not np.isfinite(values).all() or (values < 0).any() or (values > DARK).any():
        bad = values[~(np.isfinite(values) & (values >= 0) & (values <= DARK))][0]
        raise Malformed(f'{LIGHT}: readings must be finite and in [0, {DARK:g}], got {bad}')
    return Batch(episode, step, values)


def pack_bearing(episode: int, step: int, bearing_deg: np.ndarray) -> Float64MultiArray:
    return _pack(Float64MultiArray, 'd', np.float64, (episode, step),
                 np.asarray(bearing_deg, np.float64).reshape(-1, 1), 'bearing_deg')


def unpack_bearing(msg: Float64MultiArray) -> Batch:
    header, values = _unpack(msg, (1,), np.float64, BEARING)
    return Batch(*_header(header, BEARING), values)


def pack_cmd_turn(episode: int, step: int, direction, power) -> Int32MultiArray:
    cmd = np.stack([np.asarray(direction), np.asarray(power)], axis=1)
    return _pack(Int32MultiArray, 'i', np.int32, (episode, step), cmd, 'turn')


def unpack_cmd_turn(msg: Int32MultiArray) -> Batch:
    header, values = _unpack(msg, (2,), np.int32, CMD_TURN)
    episode, step = _header(header.astype(np.float64), CMD_TURN)
    direction, power = values[:, 0], values[:, 1]
    if not np.isin(direction, (-1, 1)).all():
        raise Malformed(f'{CMD_TURN}: direction must be -1 or +1, got '
                        f'{direction[~np.isin(direction, (-1, 1))][0]}')
    if ((power < 0) | (power > 9)).any():
        raise Malformed(f'{CMD_TURN}: power must be 0..9, got '
                        f'{power[(power < 0) | (power > 9)][0]}')
    return Batch(episode, step, values)


def pack_episode_start(episode: int, seeds, bearing_deg=None) -> Float64MultiArray:
    """seeds: (B,) integers < 2**53; bearing_deg: optional (B,) start bearings."""
    seeds = np.asarray(seeds, np.float64).reshape(-1, 1)
    cols = seeds if bearing_deg is None else np.hstack(
        [seeds, np.asarray(bearing_deg, np.float64).reshape(-1, 1)])
    return _pack(Float64MultiArray, 'd', np.float64, (episode,), cols, 'seed_bearing')


def unpack_episode_start(msg: Float64MultiArray) -> tuple[int, np.ndarray, np.ndarray | None]:
    """(episode, seeds (B,) int64, start bearings (B,) or None)."""
    header, values = _unpack(msg, (1, 2), np.float64, EPISODE_START)
    (episode,) = _header(header, EPISODE_START, size=1)
    seeds = values[:, 0]
    if not np.isfinite(seeds).all() or (seeds < 0).any() or (seeds >= MAX_EPISODE).any() \
            or (seeds != np.floor(seeds)).any():
        raise Malformed(f'{EPISODE_START}: seeds must be integers in [0, 2**53), got '
                        f'{seeds[:4].tolist()}')
    bearing = None
    if values.shape[1] == 2:
        bearing = values[:, 1]
        if not np.isfinite(bearing).all():
            raise Malformed(f'{EPISODE_START}: start bearings must be finite degrees')
    return episode, seeds.astype(np.int64), bearing
