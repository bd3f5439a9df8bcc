"""The lockstep topic contract shared by every robot node, controller and manager.

Every batched message is a std_msgs MultiArray whose padding (``data_offset``)
carries a small header, so that a step's readings and commands can never be
paired across episodes or steps:

  light        Float64MultiArray  [episode, step | 8 x B readings]      robot -> controller
  cmd_turn     Int32MultiArray    [episode, step | B x (direction, power)]  controller -> robot
  bearing      Float64MultiArray  [episode, step | B x 1 lamp bearing, deg] robot (ground truth)
  episode_start Float64MultiArray [episode | B x (seed[, start bearing deg])] manager -> robot
  fitness      Float64MultiArray  [episode, steps | B x 1 episode fitness]   robot -> manager
  genomes      Float64MultiArray  [episode | B x 20 genes]          manager -> controller
  genomes_loaded Int32            episode                           controller -> manager

``light`` alone is sensor-major on the wire; ``pack_light`` takes and ``unpack_light``
gives (B, 8).  Readings are 0 (brightest) .. 525 (darkest), direction -1 or +1, power
0..9, seeds integers in [0, 2**53), start bearings finite degrees within +-1e6.
``unpack_*`` raise ``Malformed`` with the reason, whatever the bytes;
``pack_*(..., raw=True)`` gives serialized bytes, which ``unpack_*`` also take.  The
reasons for this layout are in docs/architecture.md ("The lockstep messages").
"""
from __future__ import annotations

import array
from dataclasses import dataclass
from functools import lru_cache
import struct
from typing import NamedTuple

import numpy as np
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64MultiArray, Int32MultiArray, MultiArrayDimension

from ..core.khepera import DARK, SENSORS
from ..core.network import GENES, check_genomes

LIGHT, CMD_TURN, BEARING, EPISODE_START = 'light', 'cmd_turn', 'bearing', 'episode_start'
FITNESS, GENOMES, GENOMES_LOADED = 'fitness', 'genomes', 'genomes_loaded'
HEADER = 2                    # episode, step
MAX_EPISODE = 2 ** 31         # episode ids and steps must fit cmd_turn's int32 header
MAX_SEED = 2 ** 53            # seeds must be exact in a float64
MAX_BEARING_DEG = 1e6         # start bearings wrap to one turn; far beyond, float64 noise
QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                 reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


class Malformed(ValueError):
    """A message that breaks the contract; the reason names the field and value."""


class Batch(NamedTuple):     # a tuple: built twice a step, it must be cheap
    episode: int
    step: int
    values: np.ndarray        # (B, columns)


def _dims(robots: int, columns: int, label: str, by_column: bool) -> list[tuple]:
    """(label, size, stride) of the two dimensions: robots first, or (``by_column``) the
    columns first, each a row of B values."""
    if by_column:
        return [(label, columns, columns * robots), ('robots', robots, robots)]
    return [('robots', robots, robots * columns), (label, columns, columns)]


def _layout(msg, robots: int, columns: int, label: str, offset: int, by_column: bool = False):
    msg.layout.dim = [MultiArrayDimension(label=name, size=size, stride=stride)
                      for name, size, stride in _dims(robots, columns, label, by_column)]
    msg.layout.data_offset = offset
    return msg


def _pack(msg_type, typecode: str, dtype, header, values, label: str, raw: bool = False,
          cols: list | None = None, by_column: bool = False):
    """``values``: (B, columns); or None, and ``cols`` a list of the columns (B values each).
    ``by_column``: the data hold each column's B values in turn (the layout says so)."""
    if cols:
        table = np.empty((np.size(cols[0]), len(cols)), dtype)
        for k, col in enumerate(cols):
            table[:, k] = col
    else:
        table = np.asarray(values)
    robots, columns = table.shape
    # in the data's order, with the cast: one pass (none for columns packed above)
    data = np.asarray(table.T if by_column else table, dtype, order='C').tobytes()
    head = struct.pack(f'<{len(header)}{typecode}', *header)
    if raw:     # few calls: at the sizes of a lockstep step, calls cost more than bytes
        return b''.join((_cdr_prefix(robots, columns, label, len(header),
                                     np.dtype(dtype).itemsize, by_column), head, data))
    msg = _layout(msg_type(), robots, columns, label, len(header), by_column)
    msg.data = array.array(typecode, head + data)   # from bytes: no per-element loop
    return msg


# --- serialized messages: CDR, little endian ---------------------------------------------
# MultiArray = dim: sequence<(string label, uint32 size, uint32 stride)>, uint32 data_offset,
# data: sequence<T>.  Lengths are uint32; every field is aligned to its size, counted from
# the end of the 4-byte encapsulation header.  Padding bytes carry no meaning.

_CDR_LE = b'\x00\x01\x00\x00'


@lru_cache(maxsize=64)
def _cdr_prefix(robots: int, columns: int, label: str, offset: int, itemsize: int,
                by_column: bool = False) -> bytes:
    """Everything before the first array element; it depends only on the shape."""
    out = bytearray(_CDR_LE)

    def put(fmt: str, *values) -> None:
        out.extend(b'\0' * (-(len(out) - 4) % 4))
        out.extend(struct.pack(fmt, *values))
    put('<I', 2)
    for name, size, stride in _dims(robots, columns, label, by_column):
        text = name.encode() + b'\0'
        put(f'<I{len(text)}s', len(text), text)
        put('<II', size, stride)
    put('<II', offset, offset + robots * columns)
    out.extend(b'\0' * (-(len(out) - 4) % itemsize))
    return bytes(out)


@dataclass(frozen=True)
class _Layout:
    """A checked layout of a serialized MultiArray: what precedes its data."""
    prefix: bytes           # every byte before the first element
    header: struct.Struct   # the data_offset elements before the values
    robots: int
    width: int
    by_column: bool


_KNOWN: dict[str, _Layout] = {}     # topic -> the layout its last good message had


def _cdr_fields(buf, dtype, name: str) -> tuple[int, list[int], np.ndarray, int]:
    """(data_offset, dimension sizes, data, bytes before the data) of a serialized
    MultiArray."""
    if bytes(buf[:2]) != _CDR_LE[:2]:
        raise Malformed(f'{name}: serialized message must be little-endian CDR, got header '
                        f'{bytes(buf[:4]).hex() or "(empty)"}')
    pos = 4

    def u32() -> int:
        nonlocal pos
        pos += -(pos - 4) % 4
        (value,) = struct.unpack_from('<I', buf, pos)
        pos += 4
        return value
    try:
        dims, sizes = u32(), []
        if dims != 2:
            raise Malformed(f'{name}: layout must have 2 dimensions, got {dims}')
        for _ in range(dims):
            label = u32()
            pos += label                                    # skip the label
            sizes.append(u32())
            u32()                                           # the stride
        offset, count = u32(), u32()
        pos += -(pos - 4) % np.dtype(dtype).itemsize
        return offset, sizes, np.frombuffer(buf, dtype, count, pos), pos
    except Malformed:
        raise
    except (struct.error, ValueError) as exc:
        raise Malformed(f'{name}: serialized message is truncated or corrupt: {exc}') from None


def _unpack(msg, columns: tuple[int, ...], dtype, name: str, by_column: bool = False
            ) -> tuple[tuple, np.ndarray]:
    """(header as Python numbers, values (B, columns)) after checking the layout against
    the data; ``msg`` is a message or its serialized bytes.  ``by_column``: the layout is
    (columns, robots), and the values are a view of the data transposed.

    A lockstep topic keeps one layout for a whole episode: serialized bytes that begin
    with the last good message's prefix have its layout, and skip the parse and checks
    (half an unpack).
    """
    known = _KNOWN.get(name) if type(msg) is bytes else None
    if known is not None and msg.startswith(known.prefix):
        try:
            data = np.frombuffer(msg, dtype, known.robots * known.width,
                                 len(known.prefix) + known.header.size)
            return known.header.unpack_from(msg, len(known.prefix)), (
                data.reshape(known.width, known.robots).T if known.by_column
                else data.reshape(known.robots, known.width))
        except (struct.error, ValueError) as exc:
            raise Malformed(f'{name}: serialized message is truncated: {exc}') from None
    serialized = isinstance(msg, (bytes, bytearray, memoryview))
    if serialized:
        offset, sizes, data, start = _cdr_fields(msg, dtype, name)
    else:
        offset, sizes = msg.layout.data_offset, [d.size for d in msg.layout.dim]
        data = np.frombuffer(msg.data, dtype=dtype) if len(msg.data) else np.empty(0, dtype)
    shape = f'({columns[0]}, robots)' if by_column else f'(robots, {columns[0]})'
    if len(sizes) != 2:
        raise Malformed(f'{name}: layout must have 2 dimensions {shape}, got {len(sizes)}')
    width, robots = sizes if by_column else sizes[::-1]
    if width not in columns:
        raise Malformed(f'{name}: layout must be {shape} with '
                        f'{" or ".join(map(str, columns))} columns, got {width}')
    if robots < 1 or data.size != offset + robots * width:
        raise Malformed(f'{name}: {data.size} values do not fit header {offset} + '
                        f'{robots} robots x {width}')
    if type(msg) is bytes and offset <= HEADER:
        _KNOWN[name] = _Layout(bytes(msg[:start]), struct.Struct(f'<{offset}{data.dtype.char}'),
                               robots, width, by_column)
    values = data[offset:]
    return tuple(data[:offset].tolist()), (values.reshape(width, robots).T if by_column
                                           else values.reshape(robots, width))


def _header(tag: tuple, name: str, size: int = HEADER) -> tuple[int, ...]:
    try:
        ids = tuple(map(int, tag))
    except (ValueError, OverflowError):                 # NaN, inf
        ids = ()
    if len(ids) != size or ids != tag or min(ids) < 0 or max(ids) >= MAX_EPISODE:
        raise Malformed(f'{name}: header must be {size} integers in [0, 2**31), got '
                        f'{list(tag)}')
    return ids


_BITS = {np.dtype(np.float32): np.uint32, np.dtype(np.float64): np.uint64}


@lru_cache(maxsize=16)
def _top_bits(dtype: np.dtype, high: float):
    return _BITS[dtype], np.array(high, dtype).view(_BITS[dtype])[()]


def within(values: np.ndarray, high: float) -> bool:
    """Is every value in [0, high] (NaN is not)?  One pass where it can: non-negative
    floats order as their bit patterns, and negative numbers, inf and NaN lie above
    ``high``'s; only then are both ends checked (which admits -0.0)."""
    if values.dtype in _BITS and values.size:
        bits, top = _top_bits(values.dtype, high)
        if values.view(bits).max() <= top:
            return True
    return bool(values.min() >= 0 and values.max() <= high)         # NaN fails both


def _check_tag(*tag: int) -> None:
    if not all(0 <= t < MAX_EPISODE for t in tag):
        raise ValueError(f'episode ids and steps must be integers in [0, 2**31), got {tag}')


def pack_light(episode: int, step: int, readings: np.ndarray, raw: bool = False):
    """readings: (B, 8) for B robots; ``raw``: serialized bytes instead of a message."""
    return _pack(Float64MultiArray, 'd', np.float64, (episode, step), readings, 'sensors', raw,
                 by_column=True)


def unpack_light(msg: Float64MultiArray | bytes) -> Batch:
    header, values = _unpack(msg, (SENSORS,), np.float64, LIGHT, by_column=True)
    episode, step = _header(header, LIGHT)
    if not within(values, DARK):
        bad = values[~(np.isfinite(values) & (values >= 0) & (values <= DARK))][0]
        raise Malformed(f'{LIGHT}: readings must be finite and in [0, {DARK:g}], got {bad}')
    return Batch(episode, step, values)


def pack_bearing(episode: int, step: int, bearing_deg: np.ndarray, raw: bool = False):
    return _pack(Float64MultiArray, 'd', np.float64, (episode, step),
                 np.asarray(bearing_deg, np.float64).reshape(-1, 1), 'bearing_deg', raw)


def unpack_bearing(msg: Float64MultiArray | bytes) -> Batch:
    header, values = _unpack(msg, (1,), np.float64, BEARING)
    return Batch(*_header(header, BEARING), values)


def pack_fitness(episode: int, steps: int, fitness: np.ndarray, raw: bool = False):
    """fitness: (B,) episode fitness after ``steps`` steps."""
    return _pack(Float64MultiArray, 'd', np.float64, (episode, steps),
                 np.asarray(fitness, np.float64).reshape(-1, 1), 'fitness', raw)


def unpack_fitness(msg: Float64MultiArray | bytes) -> Batch:
    """Batch(episode, steps, fitness (B, 1))."""
    header, values = _unpack(msg, (1,), np.float64, FITNESS)
    episode, steps = _header(header, FITNESS)
    if not within(values, 1.0):
        bad = values[~((values >= 0) & (values <= 1))][0]
        raise Malformed(f'{FITNESS}: episode fitness must be in [0, 1], got {bad}')
    return Batch(episode, steps, values)


def pack_cmd_turn(episode: int, step: int, direction, power, raw: bool = False):
    _check_tag(episode, step)
    return _pack(Int32MultiArray, 'i', np.int32, (episode, step), None, 'turn', raw,
                 cols=[direction, power])


def unpack_cmd_turn(msg: Int32MultiArray | bytes) -> Batch:
    header, values = _unpack(msg, (2,), np.int32, CMD_TURN)
    episode, step = _header(header, CMD_TURN)
    # as uint32, -1 and +1 plus one are 0 and 2 (their OR keeps no other bit), and a
    # negative power is above 9: three calls where abs, !=, any, min, max took five
    bits = values.view(np.uint32)
    if np.bitwise_or.reduce(bits[:, 0] + np.uint32(1)) | 2 != 2:
        direction = values[:, 0]
        raise Malformed(f'{CMD_TURN}: direction must be -1 or +1, got '
                        f'{direction[np.abs(direction) != 1][0]}')
    if bits[:, 1].max() > 9:
        power = values[:, 1]
        raise Malformed(f'{CMD_TURN}: power must be 0..9, got '
                        f'{power[(power < 0) | (power > 9)][0]}')
    return Batch(episode, step, values)


def pack_genomes(episode: int, genomes, raw: bool = False):
    """genomes: (B, 20), one network per robot of the episode, in the order of its seeds."""
    _check_tag(episode)
    return _pack(Float64MultiArray, 'd', np.float64, (episode,), genomes, 'genes', raw)


def unpack_genomes(msg: Float64MultiArray | bytes) -> tuple[int, np.ndarray]:
    """(episode, genomes (B, 20)), the genes finite and within +-network.MAX_GENE."""
    header, values = _unpack(msg, (GENES,), np.float64, GENOMES)
    (episode,) = _header(header, GENOMES, size=1)
    try:
        return episode, check_genomes(values)
    except ValueError as exc:
        raise Malformed(f'{GENOMES}: {exc}') from None


def pack_episode_start(episode: int, seeds, bearing_deg=None, raw: bool = False):
    """seeds: (B,) integers < 2**53; bearing_deg: optional (B,) start bearings."""
    _check_tag(episode)
    seeds = np.asarray(seeds, np.float64).reshape(-1, 1)
    cols = seeds if bearing_deg is None else np.hstack(
        [seeds, np.asarray(bearing_deg, np.float64).reshape(-1, 1)])
    return _pack(Float64MultiArray, 'd', np.float64, (episode,), cols, 'seed_bearing', raw)


def unpack_episode_start(msg: Float64MultiArray | bytes
                         ) -> tuple[int, np.ndarray, np.ndarray | None]:
    """(episode, seeds (B,) int64, start bearings (B,) or None)."""
    header, values = _unpack(msg, (1, 2), np.float64, EPISODE_START)
    (episode,) = _header(header, EPISODE_START, size=1)
    seeds = values[:, 0]
    if not np.isfinite(seeds).all() or (seeds < 0).any() or (seeds >= MAX_SEED).any() \
            or (seeds != np.floor(seeds)).any():
        raise Malformed(f'{EPISODE_START}: seeds must be integers in [0, 2**53), got '
                        f'{seeds[:4].tolist()}')
    bearing = None
    if values.shape[1] == 2:
        bearing = values[:, 1]
        if not (np.abs(bearing) <= MAX_BEARING_DEG).all():      # NaN fails too
            raise Malformed(f'{EPISODE_START}: start bearings must be finite degrees '
                            f'within +-{MAX_BEARING_DEG:g}, got '
                            f'{bearing[~(np.abs(bearing) <= MAX_BEARING_DEG)][0]}')
    return episode, seeds.astype(np.int64), bearing
