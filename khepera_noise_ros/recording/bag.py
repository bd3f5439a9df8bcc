"""Recordings as rosbag2 directories with MCAP storage, for ``ros2 bag``, Foxglove, PlotJuggler.

The bag carries the node graph's own topics (``light``, ``bearing``, ``cmd_turn``), one
robot per message, plus ``recording/manifest`` (the YAML manifest, once, first) and
``recording/condition`` (the label from a sample on).  Reading joins the topics on
(episode, step), never on time, so a bag re-recorded with ``ros2 bag record`` reads the
same.  ``rosbags`` is imported lazily: only bag users need it.
"""
from __future__ import annotations

import math
import struct
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any, Callable, Sequence

import numpy as np
import yaml
from numpy.typing import NDArray

from ..files import StrPath, replace_tree, staging_path
from .model import (Recording, RecordingError, check_manifest, check_sequence,
                    dump_manifest, finish_manifest, first_bad_row)

if TYPE_CHECKING:
    from rosbags.interfaces import Connection, Qos
    from rosbags.typesys.store import Typestore

LIGHT, BEARING, CMD_TURN = 'light', 'bearing', 'cmd_turn'
MANIFEST, CONDITION = 'recording/manifest', 'recording/condition'
TYPES = {LIGHT: 'std_msgs/msg/Float64MultiArray', BEARING: 'std_msgs/msg/Float64MultiArray',
         CMD_TURN: 'std_msgs/msg/Int32MultiArray', MANIFEST: 'std_msgs/msg/String',
         CONDITION: 'std_msgs/msg/String'}
HEADER = 2                                     # episode, step in the MultiArray padding


def _rosbags() -> tuple[ModuleType, Typestore]:
    """(rosbag2 module, typestore), or an ImportError that says what to install."""
    try:
        from rosbags import rosbag2
        from rosbags.typesys import Stores, get_typestore
    except ImportError as exc:
        raise ImportError(f'rosbag2 recordings need the rosbags library ({exc}); install it '
                          f'with: pip install rosbags') from None
    return rosbag2, get_typestore(getattr(Stores, 'ROS2_KILTED', Stores.LATEST))


# -- writing ------------------------------------------------------------------------------

def write_bag(rec: Recording, path: StrPath, namespace: str = '', start_ns: int = 0,
              overwrite: bool = False) -> Path:
    """Write ``rec`` as a rosbag2 directory with MCAP storage; returns the path."""
    rosbag2, store = _rosbags()
    rec.check()
    manifest = finish_manifest(rec)
    path = Path(path)
    if path.exists():
        if not (overwrite and (path / 'metadata.yaml').is_file()):
            raise FileExistsError(f'{path} exists; choose another name'
                                  + ('' if overwrite else ' or allow overwriting'))
    period_ns = manifest['sample_period_s'] * 1e9
    staged = staging_path(path)         # the old bag stays until the new one is complete
    writer = rosbag2.Writer(staged, version=9, storage_plugin=rosbag2.StoragePlugin.MCAP)
    with writer:
        conn = {t: writer.add_connection(_topic(namespace, t), TYPES[t], typestore=store,
                                         offered_qos_profiles=[_qos(t)])
                for t in TYPES}

        def put(topic: str, stamp: int, msg: object) -> None:
            writer.write(conn[topic], stamp, store.serialize_cdr(msg, TYPES[topic]))

        put(MANIFEST, start_ns, _string(store, dump_manifest(manifest)))
        previous = None
        for i in range(len(rec)):
            stamp = start_ns + int(round(i * period_ns))
            key = (int(rec.episode[i]), int(rec.step[i]))
            label = str(rec.condition[i])
            if label != previous:
                text = yaml.safe_dump({'episode': key[0], 'step': key[1], 'condition': label},
                                      default_flow_style=True).strip()
                put(CONDITION, stamp, _string(store, text))
                previous = label
            if not math.isnan(rec.heading_deg[i]):
                put(BEARING, stamp, _multiarray(store, BEARING, key, [rec.heading_deg[i]]))
            put(LIGHT, stamp, _multiarray(store, LIGHT, key, rec.readings[i]))
            if not math.isnan(rec.direction[i]):
                put(CMD_TURN, stamp, _multiarray(store, CMD_TURN, key,
                                                 [rec.direction[i], rec.power[i]]))
    return replace_tree(staged, path)


def _qos(topic: str) -> Qos:
    """The graph's QoS (reliable, volatile, keep last 10); the manifest is latched."""
    from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness,
                                    QosReliability, QosTime)
    latched = topic in (MANIFEST, CONDITION)
    never = QosTime(0, 0)
    return Qos(QosHistory.KEEP_LAST, 10, QosReliability.RELIABLE,
               QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE,
               never, never, QosLiveliness.AUTOMATIC, never, False)


def _topic(namespace: str, name: str) -> str:
    return '/' + '/'.join(p for p in (namespace.strip('/'), name) if p)


def _string(store: Typestore, text: str) -> object:
    return store.types[TYPES[MANIFEST]](data=text)


def _multiarray(store: Typestore, topic: str, key: tuple[int, int],
                values: Sequence[float] | NDArray[np.float64]) -> object:
    """One robot's row with the (episode, step) header in the padding, as protocol.py packs."""
    dtype = np.int32 if topic == CMD_TURN else np.float64
    label = {LIGHT: 'sensors', BEARING: 'bearing_deg', CMD_TURN: 'turn'}[topic]
    width = len(values)
    dim = store.types['std_msgs/msg/MultiArrayDimension']
    dims = [dim(label='robots', size=1, stride=width), dim(label=label, size=width, stride=width)]
    if topic == LIGHT:                  # sensor-major, as the live topic
        dims = [dim(label=label, size=width, stride=width), dim(label='robots', size=1, stride=1)]
    layout = store.types['std_msgs/msg/MultiArrayLayout'](dim=dims, data_offset=HEADER)
    data = np.concatenate([np.asarray(key, dtype), np.asarray(values, np.float64).astype(dtype)])
    return store.types[TYPES[topic]](layout=layout, data=data)


# -- reading ------------------------------------------------------------------------------

def read_bag(path: StrPath) -> Recording:
    """Read a rosbag2 directory written by ``write_bag`` (or recorded from the topics)."""
    rosbag2, store = _rosbags()
    from rosbags.serde import SerdeError
    path = Path(path)
    if not (path / 'metadata.yaml').is_file():
        raise FileNotFoundError(f'{path}: not a rosbag2 directory (no metadata.yaml)')
    try:
        with rosbag2.Reader(path) as reader:
            topics = _find_topics(path, reader.connections)
            parsed = _Parsed(path, topics)
            for connection, _, raw in reader.messages(list(topics.values())):
                parsed.add(connection, store.deserialize_cdr(raw, connection.msgtype))
    # damaged (rosbags meets a mistyped metadata value, a string duration, as TypeError)
    except (rosbag2.ReaderError, SerdeError, struct.error, AssertionError, KeyError,
            IndexError, ValueError, TypeError, MemoryError, OverflowError, EOFError) as exc:
        if isinstance(exc, RecordingError):
            raise
        raise RecordingError(f'{path}: not a readable rosbag2 recording: '
                             f'{" ".join(str(exc).split())}') from None
    return parsed.recording()


def _find_topics(path: Path, connections: Sequence[Connection]) -> dict[str, Connection]:
    """Connection per role, matched on the topic's trailing name in any one namespace."""
    found: dict[str, Connection] = {}
    for c in connections:
        for role in TYPES:
            if c.topic == '/' + role or c.topic.endswith('/' + role):
                if role in found:
                    raise RecordingError(f'{path}: two {role} topics, {found[role].topic} and '
                                         f'{c.topic}; keep one robot per bag')
                if c.msgtype != TYPES[role]:
                    raise RecordingError(f'{path}: topic {c.topic} has type {c.msgtype}, '
                                         f'expected {TYPES[role]}')
                found[role] = c
    for role in (MANIFEST, LIGHT):
        if role not in found:
            raise RecordingError(f'{path}: no {role} topic (found '
                                 f'{sorted(c.topic for c in connections)})')
    return found


class _Parsed:
    """Messages collected per topic, each checked as it arrives."""

    def __init__(self, path: Path, topics: dict[str, Connection]) -> None:
        self.path = path
        self.role = {c.id: role for role, c in topics.items()}
        self.topic = {c.id: c.topic for c in topics.values()}
        self.count = {role: 0 for role in TYPES}
        self.manifest: dict[str, Any] | None = None
        self.light: list[tuple[tuple[int, int], NDArray[np.float64], int]] = []
        # role -> (episode, step) -> (values, where)
        self.extra: dict[str, dict[tuple[int, int], tuple[NDArray[np.float64], str]]] = {
            BEARING: {}, CMD_TURN: {}}
        self.conditions: list[tuple[tuple[int, int], str, str]] = []

    def where(self, connection: Connection, index: int) -> str:
        return f'{self.path} {self.topic[connection.id]} message {index}'

    def add(self, connection: Connection, msg: Any) -> None:
        role = self.role[connection.id]
        index = self.count[role]
        self.count[role] += 1
        where = self.where(connection, index)
        try:
            if role == MANIFEST:
                self._add_manifest(msg.data)
            elif role == CONDITION:
                self.conditions.append((*_condition(msg.data), where))
            elif role == LIGHT:
                key, values = _unpack(msg, self.channels(), by_column=True)
                self.light.append((key, values[0], index))
            else:
                key, values = _unpack(msg, 1 if role == BEARING else 2)
                if key in self.extra[role]:
                    raise ValueError(f'duplicate (episode {key[0]}, step {key[1]})')
                self.extra[role][key] = (values[0], where)
        except ValueError as exc:
            raise RecordingError(f'{where}: {exc}') from None

    def _add_manifest(self, text: str) -> None:
        if self.manifest is not None:
            raise ValueError('a second manifest')
        try:
            manifest = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise ValueError(f'manifest is not valid YAML: {" ".join(str(exc).split())}') \
                from None
        check_manifest(manifest, manifest.get('channels', 8) if isinstance(manifest, dict)
                       else 8)
        self.manifest = manifest

    def channels(self) -> int:
        if self.manifest is None:
            raise ValueError(f'light comes before the {MANIFEST} message')
        # not checked to be an int: a manifest's 8.0 or '8' fails later as a bare TypeError
        channels: int = self.manifest.get('channels', 8)
        return channels

    def recording(self) -> Recording:
        if self.manifest is None:
            raise RecordingError(f'{self.path}: the {MANIFEST} topic has no message')
        n = len(self.light)
        rec = Recording(
            episode=np.array([k[0] for k, _, _ in self.light], np.int64).reshape(n),
            step=np.array([k[1] for k, _, _ in self.light], np.int64).reshape(n),
            heading_deg=np.full(n, np.nan), condition=np.full(n, '', dtype=object),
            readings=np.array([v for _, v, _ in self.light], np.float64).reshape(
                n, self.channels()),
            direction=np.full(n, np.nan), power=np.full(n, np.nan), manifest=self.manifest)
        row = {k: i for i, (k, _, _) in enumerate(self.light)}
        light_topic = next(t for i, t in self.topic.items() if self.role[i] == LIGHT)
        where: Callable[[int], str] = (
            lambda i: f'{self.path} {light_topic} message {self.light[i][2]}')
        check_sequence(rec, where, str(self.path), MANIFEST)
        self._join(rec, row)
        rec.condition = rec.condition.astype(str)
        bad = first_bad_row(rec)
        if bad:
            raise RecordingError(f'{where(bad[0])}: {bad[1]}')
        return rec

    def _join(self, rec: Recording, row: dict[tuple[int, int], int]) -> None:
        """Bearings, commands and conditions onto the light rows, by (episode, step)."""
        for role, values in self.extra.items():
            for key, (value, where) in values.items():
                if key not in row:
                    raise RecordingError(f'{where}: (episode {key[0]}, step {key[1]}) has no '
                                         f'light reading')
                if role == BEARING:
                    rec.heading_deg[row[key]] = value[0]
                else:
                    rec.direction[row[key]], rec.power[row[key]] = value
        starts: list[tuple[int, str]] = []
        for key, label, where in self.conditions:
            if key not in row:
                raise RecordingError(f'{where}: (episode {key[0]}, step {key[1]}) has no '
                                     f'light reading')
            starts.append((row[key], label))
        starts.sort()
        if len(rec) and (not starts or starts[0][0] != 0):
            raise RecordingError(f'{self.path}: no {CONDITION} message for the first sample')
        for (first, label), (end, _) in zip(starts, starts[1:] + [(len(rec), '')]):
            rec.condition[first:end] = label


def _condition(text: str) -> tuple[tuple[int, int], str]:
    try:
        value = yaml.safe_load(text)
        key = (int(value['episode']), int(value['step']))
        label = value['condition']
    except (yaml.YAMLError, TypeError, KeyError, ValueError):
        raise ValueError(f'expected {{episode: E, step: S, condition: LABEL}}, got {text!r}') \
            from None
    if not isinstance(label, str):
        raise ValueError(f'condition must be a label, got {label!r}')
    return key, label


def _unpack(msg: Any, width: int, by_column: bool = False
            ) -> tuple[tuple[int, int], NDArray[np.float64]]:
    """((episode, step), values (1, width)) after checking the layout against the data.

    ``by_column`` (light): the layout is (width, 1 robot), as the live topic has it; for one
    robot the data are the same either way, so (1 robot, width), as bags before it, reads too.
    """
    data = np.asarray(msg.data, np.float64)
    dims = msg.layout.dim
    offset = msg.layout.data_offset
    shape = [d.size for d in dims]
    if shape != [1, width] and not (by_column and shape == [width, 1]):
        raise ValueError(f'layout must be ({width}, 1 robot), got {shape}' if by_column
                         else f'layout must be (1 robot, {width}), got {shape}')
    if offset != HEADER or data.size != HEADER + width:
        raise ValueError(f'{data.size} values do not fit header {offset} + 1 x {width}')
    header = data[:HEADER]
    if not np.isfinite(header).all() or (header < 0).any() or (header != np.floor(header)).any():
        raise ValueError(f'header must be (episode, step) integers >= 0, got {header.tolist()}')
    return (int(header[0]), int(header[1])), data[HEADER:].reshape(1, width)
