"""Recording format I/O: CSV + YAML manifest and rosbag2 (MCAP), strict readers."""
import math

import numpy as np
import pytest
import yaml

from khepera_noise_ros import recording
from khepera_noise_ros.recording.bag import read_bag, write_bag
from khepera_noise_ros.core import network
from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.core.task import Task, run
from khepera_noise_ros.recording import (FORMAT, Recording, RecordingError, concatenate,
                                         from_trace, load, read_csv, write_csv)
from khepera_noise_ros.testing.recordings import manifest, stationary


def closed_loop(seed=3) -> Recording:
    genome = np.random.default_rng(seed).uniform(-0.4, 0.4, network.GENES)
    weights = network.unpack(genome)
    trace = run(lambda r: network.act(weights, r), [seed], task=Task(steps=15), trace=True)
    return from_trace(trace, 'bright', manifest(protocol='closed_loop',
                                                genome=genome.tolist()))


def assert_same(a: Recording, b: Recording):
    for name in ('episode', 'step', 'heading_deg', 'readings', 'direction', 'power'):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.condition.tolist() == b.condition.tolist()


def test_csv_round_trip_keeps_every_value_and_the_v1_layout(tmp_path):
    rec = concatenate([stationary(), stationary(NoiseModel('independent', 0, .05), seed=2,
                                                condition='dim', first_episode=2)])
    csv_path, yaml_path = write_csv(rec, tmp_path / 'rec')
    lines = csv_path.read_text().splitlines()
    assert lines[0] == ','.join(recording.COLUMNS)
    assert lines[1].endswith(',,')               # stationary: direction and power empty
    saved = yaml.safe_load(yaml_path.read_text())
    assert saved['format'] == FORMAT and 'channels' not in saved
    assert saved['samples'] == len(rec) == 80 and saved['lost_steps'] == []
    back = load(tmp_path / 'rec.yaml')
    assert_same(rec, back)
    assert back.conditions() == ['bright', 'dim']
    assert back.step_problems() == ([], [])


def test_closed_loop_round_trips_through_csv_and_mcap_bag(tmp_path):
    rec = closed_loop()
    assert set(np.unique(rec.direction)) <= {-1.0, 1.0} and not np.isnan(rec.power).any()
    write_csv(rec, tmp_path / 'loop.csv')
    bag = write_bag(rec, tmp_path / 'loop_bag', namespace='khepera')
    assert (bag / 'metadata.yaml').is_file() and list(bag.glob('*.mcap'))
    from_csv, from_bag = load(tmp_path / 'loop'), read_bag(bag)
    assert_same(rec, from_csv)
    assert_same(from_csv, from_bag)
    assert from_bag.manifest['genome'] == pytest.approx(rec.manifest['genome'])


def test_a_bag_whose_metadata_has_a_mistyped_value_is_refused_in_one_line(tmp_path):
    bag = write_bag(closed_loop(), tmp_path / 'loop_bag')
    meta = bag / 'metadata.yaml'
    data = yaml.safe_load(meta.read_text())
    data['rosbag2_bagfile_information']['duration']['nanoseconds'] = 'long'
    meta.write_text(yaml.safe_dump(data))
    with pytest.raises(RecordingError, match='loop_bag: not a readable rosbag2 recording') as e:
        read_bag(bag)
    assert '\n' not in str(e.value)


def test_bag_messages_are_the_graph_protocol(tmp_path):
    """A bag written without ROS decodes with rclpy and the live topic contract."""
    from rclpy.serialization import deserialize_message
    from rosbags.rosbag2 import Reader
    from std_msgs.msg import Float64MultiArray, Int32MultiArray

    from khepera_noise_ros.nodes import protocol
    rec = closed_loop()
    write_bag(rec, tmp_path / 'b')
    decoded = {'/light': [], '/cmd_turn': [], '/bearing': []}
    with Reader(tmp_path / 'b') as reader:
        for connection, _, raw in reader.messages():
            kind = {'/light': (Float64MultiArray, protocol.unpack_light),
                    '/cmd_turn': (Int32MultiArray, protocol.unpack_cmd_turn),
                    '/bearing': (Float64MultiArray, protocol.unpack_bearing)}.get(
                        connection.topic)
            if kind:
                decoded[connection.topic].append(kind[1](deserialize_message(raw, kind[0])))
    light = decoded['/light']
    assert [(b.episode, b.step) for b in light] == list(zip(rec.episode, rec.step))
    np.testing.assert_array_equal(np.concatenate([b.values for b in light]), rec.readings)
    np.testing.assert_array_equal(np.concatenate([b.values for b in decoded['/cmd_turn']]),
                                  np.column_stack([rec.direction, rec.power]))
    np.testing.assert_array_equal([b.values[0, 0] for b in decoded['/bearing']],
                                  rec.heading_deg)


def test_other_channel_counts_round_trip_with_unused_channels_empty(tmp_path):
    n = 12
    readings = np.random.default_rng(0).integers(0, 255, (n, 10)).astype(float)
    readings[:, [4, 9]] = np.nan                      # channels the board does not use
    rec = Recording(np.repeat([0, 1], 6), np.tile(np.arange(6), 2), np.full(n, np.nan),
                    np.full(n, 'lamp'), readings, np.full(n, np.nan), np.full(n, np.nan),
                    manifest(['lamp'], source='hardware', channels_used=[0, 1, 2, 3, 5, 6, 7, 8],
                             reading_range=[0, 255]))
    csv_path, _ = write_csv(rec, tmp_path / 'board')
    header = csv_path.read_text().splitlines()[0].split(',')
    assert header[4:-2] == [f's{i}' for i in range(10)]
    for back in (read_csv(csv_path), read_bag(write_bag(rec, tmp_path / 'board_bag'))):
        assert back.channels == 10 and back.channels_used == [0, 1, 2, 3, 5, 6, 7, 8]
        np.testing.assert_array_equal(back.readings, readings)
    saved = yaml.safe_load((tmp_path / 'board.yaml').read_text())
    assert saved['channels'] == 10
    del saved['channels']                     # an undeclared channel count is refused
    (tmp_path / 'board.yaml').write_text(yaml.safe_dump(saved))
    with pytest.raises(RecordingError, match='board.yaml: channels is 8 but the data has 10'):
        read_csv(csv_path)


def test_step_problems_finds_lost_and_duplicated_steps():
    rec = stationary(headings=(0.0,), steps=6)
    keep = np.array([0, 1, 1, 3, 4, 5])              # step 2 lost, step 1 twice
    broken = rec.select(keep)
    assert broken.step_problems() == ([(0, 2)], [(0, 1)])
    with pytest.raises(RecordingError, match=r'steps recorded twice: \(episode 0, step 1\)'):
        recording.finish_manifest(broken)


def test_declared_lost_steps_are_accepted_and_undeclared_gaps_are_not(tmp_path):
    rec = stationary(headings=(0.0,), steps=6).select(np.array([0, 1, 3, 4, 5]))
    write_csv(rec, tmp_path / 'gap')
    assert load(tmp_path / 'gap').manifest['lost_steps'] == [[0, 2]]
    lines = (tmp_path / 'gap.csv').read_text().splitlines()
    (tmp_path / 'gap.csv').write_text('\n'.join(lines[:3] + lines[4:]) + '\n')  # drop step 3
    text = (tmp_path / 'gap.yaml').read_text().replace('samples: 5', 'samples: 4')
    (tmp_path / 'gap.yaml').write_text(text)
    with pytest.raises(RecordingError, match=r'gap.csv: steps missing that gap.yaml does not '
                                             r'list as lost: \(episode 0, step 3\)'):
        load(tmp_path / 'gap')


# -- strict reading of broken files -----------------------------------------------------

@pytest.fixture
def written(tmp_path):
    write_csv(stationary(), tmp_path / 'recording')
    return tmp_path / 'recording.csv'


def edit_line(path, number, new):
    lines = path.read_text().splitlines()
    lines[number - 1] = new(lines[number - 1])
    path.write_text('\n'.join(lines) + '\n')


@pytest.mark.parametrize('line, change, message', [
    (17, lambda s: ','.join(s.split(',')[:9]), 'line 17: expected 14 columns, got 9'),
    (5, lambda s: s.replace(',bright,', ',dusk,'),
     "line 5: condition 'dusk' is not in the manifest conditions"),
    (6, lambda s: s.replace(',bright,', ',bright,x7'), "line 6: s0 is not a number: 'x7"),
    (7, lambda s: s.replace(',bright,', ',bright,-4'), 'line 7: s0 must be a reading in '
                                                       r'\[0, 525\], got -4'),
    (8, lambda s: '0.5' + s[1:], "line 8: episode must be an integer of at most "
                                 r"9,007,199,254,740,992 in size, got '0.5'"),
    (10, lambda s: '0,' + '9' * 30 + s[s.index(',', 2):],
     "line 10: step must be an integer of at most 9,007,199,254,740,992 in size, got '9999"),
    (9, lambda s: s[:-1] + '1,', 'line 9: direction and power must both be given or both'),
    (1, lambda s: s.replace('s7', 'light7'), 'line 1: header must be episode,step'),
])
def test_corrupt_csv_lines_are_named(written, line, change, message):
    edit_line(written, line, change)
    with pytest.raises(RecordingError, match='recording.csv ' + message):
        read_csv(written)


def test_duplicated_line_is_named_with_its_first_occurrence(written):
    lines = written.read_text().splitlines()
    written.write_text('\n'.join(lines[:4] + [lines[2]] + lines[4:]) + '\n')
    with pytest.raises(RecordingError, match=r'recording.csv line 5: duplicate sample '
                                             r'\(episode 0, step 1\), first at .*line 3'):
        read_csv(written)


@pytest.mark.parametrize('keep_bytes, message', [
    (-30, 'expected 14 columns, got'),         # cut mid-row
    (None, 'recording.yaml says 40 samples, found 30'),       # cut at a row boundary
])
def test_truncated_csv_is_detected(written, keep_bytes, message):
    text = written.read_text()
    if keep_bytes is None:
        text = '\n'.join(text.splitlines()[:31]) + '\n'
    else:
        text = text[:keep_bytes]
    written.write_text(text)
    with pytest.raises(RecordingError, match=message):
        read_csv(written)


def test_bad_manifest_names_the_file_and_line(written):
    manifest_path = written.with_suffix('.yaml')
    text = manifest_path.read_text()
    manifest_path.write_text(text.replace('sample_period_s: 1.0', 'sample_period_s: [1.0'))
    with pytest.raises(RecordingError, match=r'recording.yaml line \d+: not valid YAML'):
        read_csv(written)
    manifest_path.write_text(text.replace('sample_period_s: 1.0', 'sample_period_s: -1'))
    with pytest.raises(RecordingError, match='recording.yaml: sample_period_s must be a '
                                             'positive number, got -1'):
        read_csv(written)
    manifest_path.write_text(text.replace(FORMAT, 'khepera-noise-recording/9'))
    with pytest.raises(RecordingError, match="format must be 'khepera-noise-recording/1'"):
        read_csv(written)


def test_binary_and_missing_files(tmp_path, written):
    written.write_bytes(b'\xff\xfe\x00garbage')
    with pytest.raises(RecordingError, match='recording.csv: not a text file'):
        read_csv(written)
    with pytest.raises(FileNotFoundError, match='nothing.csv: no such file'):
        load(tmp_path / 'nothing')


def test_truncated_bag_is_named(tmp_path):
    bag = write_bag(stationary(), tmp_path / 'cut_bag')
    mcap = next(bag.glob('*.mcap'))
    mcap.write_bytes(mcap.read_bytes()[: mcap.stat().st_size // 2])
    with pytest.raises(RecordingError, match='cut_bag: not a readable rosbag2 recording'):
        read_bag(bag)


def write_raw_bag(path, light_layout, with_manifest=True):
    """A bag with one hand-made light message, for malformed-message tests."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS2_KILTED)
    t = store.types
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        if with_manifest:
            c = writer.add_connection('/recording/manifest', 'std_msgs/msg/String',
                                      typestore=store)
            text = recording.dump_manifest(manifest())
            writer.write(c, 0, store.serialize_cdr(t['std_msgs/msg/String'](data=text),
                                                   'std_msgs/msg/String'))
            c = writer.add_connection('/recording/condition', 'std_msgs/msg/String',
                                      typestore=store)
            text = '{episode: 0, step: 0, condition: bright}'
            writer.write(c, 1, store.serialize_cdr(t['std_msgs/msg/String'](data=text),
                                                   'std_msgs/msg/String'))
        c = writer.add_connection('/light', 'std_msgs/msg/Float64MultiArray', typestore=store)
        dims, offset, data = light_layout
        layout = t['std_msgs/msg/MultiArrayLayout'](
            dim=[t['std_msgs/msg/MultiArrayDimension'](label='', size=s, stride=s)
                 for s in dims], data_offset=offset)
        msg = t['std_msgs/msg/Float64MultiArray'](layout=layout, data=np.asarray(data, float))
        writer.write(c, 1, store.serialize_cdr(msg, 'std_msgs/msg/Float64MultiArray'))


@pytest.mark.parametrize('layout, with_manifest, message', [
    (((1, 8), 2, [0, 0] + [100] * 7), True, r'/light message 0: 9 values do not fit header'),
    (((1, 6), 2, [0, 0] + [100] * 6), True, r'/light message 0: layout must be \(8, 1 robot\)'),
    (((1, 8), 2, [0, -1] + [100] * 8), True, r'/light message 0: header must be'),
    (((1, 8), 2, [0, 0] + [600] * 8), True, r'/light message 0: s0 must be a reading in'),
    (((1, 8), 2, [0, 0] + [100] * 8), False, 'no recording/manifest topic'),
])
def test_malformed_bag_messages_are_named(tmp_path, layout, with_manifest, message):
    write_raw_bag(tmp_path / 'raw', layout, with_manifest)
    with pytest.raises(RecordingError, match=message):
        read_bag(tmp_path / 'raw')


def test_writer_refuses_bad_recordings(tmp_path):
    rec = stationary(headings=(0.0,), steps=4)
    rec.readings[2, 5] = math.nan
    with pytest.raises(RecordingError, match='sample 2: s5 is empty but channels_used'):
        write_csv(rec, tmp_path / 'bad')
    rec.readings[2, 5] = 100
    rec.manifest = {**rec.manifest, 'source': 'dream'}
    with pytest.raises(RecordingError, match="source must be one of"):
        write_bag(rec, tmp_path / 'bad_bag')
