"""The lockstep topic contract: round trips, and every malformed message named."""
import array

import numpy as np
import pytest
from rclpy.logging import LoggingSeverity
from rclpy.node import Node
from rclpy.qos import ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64MultiArray, Int32MultiArray

from khepera_noise_ros.nodes import protocol
from khepera_noise_ros.nodes.dropped import Dropped
from khepera_noise_ros.nodes.graph import EpisodeIds, episode_fitness
from khepera_noise_ros.core.task import step_fitness

READINGS = np.random.default_rng(0).integers(0, 526, (8, 5)).astype(np.float32)


def test_round_trips_keep_tags_and_values():
    light = protocol.unpack_light(protocol.pack_light(2 ** 31 - 1, 59, READINGS.T))
    assert (light.episode, light.step) == (2 ** 31 - 1, 59)
    np.testing.assert_array_equal(light.values, READINGS.T)
    cmd = protocol.unpack_cmd_turn(protocol.pack_cmd_turn(4, 3, [1, -1], [0, 9]))
    assert (cmd.episode, cmd.step) == (4, 3) and cmd.values.tolist() == [[1, 0], [-1, 9]]
    episode, seeds, bearing = protocol.unpack_episode_start(
        protocol.pack_episode_start(6, [2 ** 53 - 1, 0], [10.0, -20.5]))
    assert episode == 6 and seeds.tolist() == [2 ** 53 - 1, 0]
    assert bearing.tolist() == [10.0, -20.5]
    assert protocol.QOS.reliability == ReliabilityPolicy.RELIABLE and protocol.QOS.depth >= 10


@pytest.mark.parametrize('robots', [1, 2, 3, 1024])
def test_serialized_messages_are_the_bytes_rclpy_sends(robots):
    """raw=True packs what rclpy would serialize; unpack reads what rclpy serializes."""
    rng = np.random.default_rng(robots)
    readings = rng.integers(0, 526, (robots, 8)).astype(np.float64)
    direction, power = rng.choice([-1, 1], robots), rng.integers(0, 10, robots)
    cases = [(protocol.pack_light, (5, 6, readings), Float64MultiArray, protocol.unpack_light),
             (protocol.pack_cmd_turn, (5, 6, direction, power), Int32MultiArray,
              protocol.unpack_cmd_turn),
             (protocol.pack_bearing, (5, 6, readings[:, 0] / 3), Float64MultiArray,
              protocol.unpack_bearing)]
    for pack, args, msg_type, unpack in cases:
        raw, msg = pack(*args, raw=True), pack(*args)
        back = deserialize_message(raw, msg_type)
        assert back.layout == msg.layout and np.array_equal(back.data, msg.data)
        assert len(raw) == len(serialize_message(msg))
        ours, theirs = unpack(raw), unpack(serialize_message(msg))
        assert (ours.episode, ours.step) == (theirs.episode, theirs.step) == (5, 6)
        np.testing.assert_array_equal(ours.values, theirs.values)
    episode, seeds, bearing = protocol.unpack_episode_start(serialize_message(
        protocol.pack_episode_start(9, np.arange(robots), np.arange(robots) / 2)))
    assert episode == 9 and seeds.tolist() == list(range(robots))
    assert bearing.tolist() == [i / 2 for i in range(robots)]


@pytest.mark.parametrize('damage, words', [
    (lambda raw: raw[:1], 'little-endian CDR'),
    (lambda raw: raw[:6], 'truncated or corrupt'),
    (lambda raw: b'\x00\x00\x00\x00' + raw[4:], 'little-endian CDR'),
    (lambda raw: raw[:60], 'truncated or corrupt'),
    (lambda raw: raw[:4] + b'\xff\xff\xff\xff' + raw[8:], 'must have 2 dimensions, got'),
    (lambda raw: raw[:8] + b'\xff\xff\xff\x0f' + raw[12:], 'truncated or corrupt'),
])
def test_damaged_serialized_messages_are_malformed(damage, words):
    raw = protocol.pack_light(1, 2, READINGS.T, raw=True)
    with pytest.raises(protocol.Malformed, match=words):
        protocol.unpack_light(damage(raw))


def _with_data(msg, index, value):
    data = np.frombuffer(msg.data, dtype=np.float64).copy()
    data[index] = value
    msg.data = array.array('d', data.tobytes())
    return msg


@pytest.mark.parametrize('make, unpack, words', [
    (lambda: _with_data(protocol.pack_light(1, 0, READINGS.T), 7, np.nan),
     protocol.unpack_light, 'readings must be finite and in [0, 525], got nan'),
    (lambda: _with_data(protocol.pack_light(1, 0, READINGS.T), 3, 526.0),
     protocol.unpack_light, 'got 526'),
    (lambda: _with_data(protocol.pack_light(1, 0, READINGS.T), 1, 0.5),
     protocol.unpack_light, 'header must be 2 integers'),
    (lambda: _with_data(protocol.pack_light(1, 0, READINGS.T), 0, 2.0 ** 31),
     protocol.unpack_light, 'header must be 2 integers'),
    (lambda: _with_data(protocol.pack_episode_start(1, [3]), 1, -1.0),
     protocol.unpack_episode_start, 'seeds must be integers'),
    (lambda: protocol.pack_episode_start(1, [3, 4], [10.0, 1e300]),
     protocol.unpack_episode_start, 'start bearings must be finite degrees within +-1e+06, '
     'got 1e+300'),
    (lambda: protocol.pack_episode_start(1, [3], [np.nan]), protocol.unpack_episode_start,
     'start bearings must be finite degrees within +-1e+06, got nan'),
    (lambda: protocol.pack_cmd_turn(1, 0, [1, 0], [1, 1]), protocol.unpack_cmd_turn,
     'direction must be -1 or +1, got 0'),
    (lambda: protocol.pack_cmd_turn(1, 0, [1, 1], [1, 10]), protocol.unpack_cmd_turn,
     'power must be 0..9, got 10'),
    (lambda: Int32MultiArray(data=[1, 0, 1, 1]), protocol.unpack_cmd_turn,
     'layout must have 2 dimensions'),
])
def test_malformed_messages_raise_with_the_reason(make, unpack, words):
    with pytest.raises(protocol.Malformed, match=words.replace('[', r'\[').replace('+', r'\+')):
        unpack(make())


def test_light_holds_one_row_of_robots_per_sensor():
    """Sensor-major on the wire (the layout recorded bags have), (B, 8) in Python."""
    readings = np.arange(8 * 3, dtype=np.float64).reshape(8, 3)     # (sensors, robots)
    msg = protocol.pack_light(4, 5, readings.T)
    assert [(d.label, d.size, d.stride) for d in msg.layout.dim] == [('sensors', 8, 24),
                                                                     ('robots', 3, 3)]
    assert list(msg.data)[:5] == [4, 5, 0, 1, 2]            # header, then s0 of robots 0..2
    for raw in (msg, protocol.pack_light(4, 5, readings.T, raw=True)):
        assert np.array_equal(protocol.unpack_light(raw).values, readings.T)


@pytest.mark.parametrize('dtype', [np.float32, np.float64])
def test_within_is_the_closed_range_with_nan_and_inf_outside(dtype):
    def ok(*values):
        return protocol.within(np.array(values, dtype), 525.0)
    assert ok(0.0, 525.0, 17.0) and ok(-0.0, 3.0)
    for bad in (-1e-30, 525.00006, np.inf, -np.inf, np.nan, -np.nan):
        assert not ok(1.0, bad, 2.0), bad


@pytest.mark.parametrize('direction', [0, 2, -2, 3, -3, 2 ** 31 - 1, -2 ** 31, -2 ** 31 + 1])
def test_every_direction_but_plus_and_minus_one_is_refused(direction):
    raw = protocol.pack_cmd_turn(1, 0, [1, -1, direction, 1], [0, 9, 4, 2], raw=True)
    with pytest.raises(protocol.Malformed, match=f'direction must be -1 or \\+1, got '
                       f'{direction}$'):
        protocol.unpack_cmd_turn(raw)
    assert protocol.unpack_cmd_turn(protocol.pack_cmd_turn(1, 0, [1, -1], [0, 9], raw=True))


@pytest.mark.parametrize('power', [-1, 10, -2 ** 31, 2 ** 31 - 1])
def test_every_power_outside_0_to_9_is_refused(power):
    raw = protocol.pack_cmd_turn(1, 0, [1, -1, 1], [0, power, 9], raw=True)
    with pytest.raises(protocol.Malformed, match=f'power must be 0..9, got {power}$'):
        protocol.unpack_cmd_turn(raw)


def test_a_known_layout_still_refuses_bad_values_and_truncation():
    good = protocol.pack_light(1, 2, READINGS.T, raw=True)
    protocol.unpack_light(good)                       # now the topic's known layout
    bad = protocol.pack_light(1, 3, np.where(READINGS.T > 100, 600.0, READINGS.T), raw=True)
    with pytest.raises(protocol.Malformed, match='got 600'):
        protocol.unpack_light(bad)
    with pytest.raises(protocol.Malformed, match='truncated'):
        protocol.unpack_light(good[:-8])
    assert protocol.unpack_light(good).step == 2


def test_tags_that_do_not_fit_the_int32_header_are_refused_when_packing():
    with pytest.raises(ValueError, match=r'\[0, 2\*\*31\)'):
        protocol.pack_cmd_turn(2 ** 31, 0, [1], [1])
    with pytest.raises(ValueError, match=r'\[0, 2\*\*31\)'):
        protocol.pack_episode_start(-1, [1])


def test_episode_ids_are_unique_and_fit_the_header():
    ids = EpisodeIds()
    drawn = [next(ids) for _ in range(1000)]
    assert len(set(drawn)) == 1000 and all(0 <= i < protocol.MAX_EPISODE for i in drawn)
    assert next(EpisodeIds()) != next(EpisodeIds()) or next(EpisodeIds()) != next(EpisodeIds())


def test_episode_fitness_sums_like_the_core():
    rng = np.random.default_rng(1)
    readings = rng.integers(0, 526, (30, 4, 8)).astype(np.float32)
    power = rng.integers(0, 10, (30, 4))
    total = np.zeros(4, np.float32)
    for t in range(30):
        total += step_fitness(readings[t], power[t])
    np.testing.assert_array_equal(episode_fitness(readings, power), total / 30)


def test_drops_are_counted_and_warned_at_most_once_a_second_per_kind(ros_context, capfd):
    node = Node('dropper', context=ros_context)
    try:
        node.get_logger().set_level(LoggingSeverity.DEBUG)
        dropped = Dropped(node)
        for _ in range(3):
            dropped.add('malformed', 'NaN reading')
        dropped.add('wrong_robots', '3 robots, genomes hold 2')
        dropped.add('stale', 'a duplicate', warn=False)
        assert dict(dropped) == {'malformed': 3, 'wrong_robots': 1, 'stale': 1}
    finally:
        node.destroy_node()
    lines = [line for line in capfd.readouterr().err.splitlines() if 'dropped a message' in line]
    warnings = [line.split(']: ', 1)[1] for line in lines if line.startswith('[WARN]')]
    assert warnings == ['dropped a message (malformed, 1 so far): NaN reading',
                        'dropped a message (wrong_robots, 1 so far): 3 robots, genomes hold 2']
    assert len(lines) == 5 and all(line.startswith('[DEBUG]') for line in lines
                                   if not line.startswith('[WARN]'))
