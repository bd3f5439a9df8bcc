"""Converting public multi-sensor logs (written here in their published layouts) to recordings."""
import numpy as np
import pytest

from khepera_noise_ros import cli
from khepera_noise_ros.convert import convert
from khepera_noise_ros.recording import load, write_csv

HEADER = ('Date,Time,S1_Temp,S2_Temp,S3_Temp,S4_Temp,S1_Light,S2_Light,S3_Light,S4_Light,'
          'S1_Sound,S2_Sound,S3_Sound,S4_Sound,S5_CO2,S5_CO2_Slope,S6_PIR,S7_PIR,'
          'Room_Occupancy_Count')


def _occupancy_file(tmp_path, date_format='%Y/%m/%d', blank_at=None, gap_at=None, rows=40):
    """A small Room Occupancy Estimation CSV: occupancy 0 then 2 then 0, light rising with it."""
    from datetime import datetime, timedelta
    t = datetime(2017, 12, 22, 10, 0, 0)
    lines = [HEADER]
    for i in range(rows):
        count = 2 if 15 <= i < 30 else 0
        light = [100 + 50 * count + i % 3, 40 + 60 * count, 20, 10 + count]
        temp = [25.0 + 0.0625 * (i // 5), 24.5, 24.75, 25.5]
        cells = [f'{v:g}' for v in temp] + [str(v) for v in light]
        if i == blank_at:
            cells[4] = ''
        lines.append(','.join([t.strftime(date_format), t.strftime('%H:%M:%S')] + cells
                              + ['0.1', '0.1', '0.1', '0.1', '400', '0.5', '0', '0',
                                 str(count)]))
        t += timedelta(seconds=300 if i + 1 == gap_at else 30)
    path = tmp_path / 'Occupancy_Estimation.csv'
    path.write_text('\n'.join(lines) + '\n')
    return path


def test_room_occupancy_maps_channels_conditions_and_the_inversion(tmp_path):
    rec = convert('room-occupancy', _occupancy_file(tmp_path), episode_length=60, min_length=2)
    assert rec.conditions() == ['occupancy_0', 'occupancy_2']
    assert len(rec) == 40 and rec.manifest['sample_period_s'] == 30.0
    info = rec.manifest['converted_from']['channels']
    assert [info[f's{i}']['column'] for i in range(8)] == [
        'S1_Light', 'S2_Light', 'S3_Light', 'S4_Light', 'S1_Temp', 'S2_Temp', 'S3_Temp',
        'S4_Temp']
    light = rec.readings[:, :4]
    # brightest lux of all four light sensors reads 0, darkest 525; same map for all four
    assert light.min() == 0.0 and light.max() == 525.0
    low, high = info['s0']['low'], info['s0']['high']
    assert (low, high) == (10.0, 202.0)
    assert rec.readings[0, 0] == pytest.approx(525 * (202 - 100) / 192)
    # people in the room: brighter (smaller readings) on s0
    busy = rec.condition == 'occupancy_2'
    assert rec.readings[busy, 0].mean() < rec.readings[~busy, 0].mean() - 100
    # warmer = smaller reading; the temperature lattice of 0.0625 degC survives as one step
    temp = rec.readings[:, 4]
    steps = np.unique(np.round(np.abs(np.diff(temp)), 6))
    assert steps[steps > 0].min() == pytest.approx(525 * 0.0625 / (info['s4']['high']
                                                                   - info['s4']['low']))
    assert temp[-1] < temp[0]
    # episodes break where the label changes: 0 (15 samples), 2 (15), 0 (10)
    assert [int((rec.episode == e).sum()) for e in np.unique(rec.episode)] == [15, 15, 10]
    assert np.isnan(rec.heading_deg).all() and np.isnan(rec.power).all()


def test_episodes_split_at_gaps_missing_values_and_the_length_limit(tmp_path):
    rec = convert('room-occupancy', _occupancy_file(tmp_path, blank_at=5, gap_at=10),
                  episode_length=4, min_length=1)
    lengths = [int((rec.episode == e).sum()) for e in np.unique(rec.episode)]
    assert max(lengths) <= 4
    assert len(rec) == 39                      # the row with a blank is dropped
    assert rec.manifest['converted_from']['dropped_samples'] == 1
    # no episode spans the missing row (sample 5) or the clock jump before sample 10
    kept = [i for i in range(40) if i != 5]
    for e in np.unique(rec.episode):
        rows = [kept[i] for i in np.flatnonzero(rec.episode == e)]
        assert not (rows[0] < 5 < rows[-1]) and not (rows[0] < 10 <= rows[-1])
    short = convert('room-occupancy', _occupancy_file(tmp_path, blank_at=5, gap_at=10),
                    episode_length=4, min_length=2)
    # runs 0-4 and 10-14 are cut into 4 + 1: both single leftovers are dropped
    assert len(short) == len(rec) - 2
    assert min(int((short.episode == e).sum()) for e in np.unique(short.episode)) >= 2


def test_date_layouts_and_a_file_without_clock_agree(tmp_path):
    a = convert('room-occupancy', _occupancy_file(tmp_path, '%Y/%m/%d'), min_length=2)
    b = convert('room-occupancy', _occupancy_file(tmp_path, '%d-%m-%Y'), min_length=2)
    np.testing.assert_array_equal(a.readings, b.readings)
    path = _occupancy_file(tmp_path)
    lines = path.read_text().splitlines()
    path.write_text('\n'.join(','.join(line.split(',')[2:]) for line in lines) + '\n')
    c = convert('room-occupancy', path, min_length=2)
    np.testing.assert_array_equal(a.readings, c.readings)
    assert c.manifest['sample_period_s'] == 30.0


def test_the_recording_round_trips_through_the_public_writer(tmp_path):
    rec = convert('room-occupancy', _occupancy_file(tmp_path), min_length=2,
                  channels=['S1_Light', 'S2_Light', 'S3_Light'])
    assert rec.manifest['channels_used'] == [0, 1, 2]
    write_csv(rec, tmp_path / 'out' / 'room')
    back = load(tmp_path / 'out' / 'room')
    np.testing.assert_allclose(back.readings[:, :3], rec.readings[:, :3])
    assert back.manifest['converted_from']['channels']['s2']['column'] == 'S3_Light'


def _intel_file(tmp_path):
    """data.txt lines: epoch every 31 s, motes 1-3; mote 3 misses epoch 2; one short line."""
    from datetime import datetime, timedelta
    t0 = datetime(2004, 2, 28, 18, 58, 0)
    lines = []
    for epoch in range(6):
        for mote in (1, 2, 3, 9):
            if (epoch, mote) == (2, 3):
                continue
            t = t0 + timedelta(seconds=31 * epoch + mote)
            light = 100.0 * mote + epoch
            lines.append(f'{t:%Y-%m-%d %H:%M:%S}.{mote * 1000:06d} {epoch} {mote} '
                         f'{19 + 0.1 * epoch:.4f} 37.1 {light:g} 2.69')
    lines.insert(3, '2004-02-28 19:00:00.1 7 1 19.9')
    path = tmp_path / 'data.txt'
    path.write_text('\n'.join(lines) + '\n')
    return path


def test_intel_lab_keeps_epochs_where_every_chosen_mote_reported(tmp_path):
    rec = convert('intel-lab', _intel_file(tmp_path), motes=[1, 2, 3], min_length=1,
                  episode_length=60)
    assert len(rec) == 5                       # epoch 2 lacks mote 3
    assert rec.manifest['channels_used'] == [0, 1, 2]
    # brighter mote (more lux) reads lower; day until 19:00 then night
    assert (rec.readings[:, 2] < rec.readings[:, 0]).all()
    assert rec.conditions() == ['day', 'night']
    assert rec.manifest['sample_period_s'] == 31.0
    temp = convert('intel-lab', _intel_file(tmp_path), motes=[1, 2], quantity='temperature',
                   min_length=1)
    assert temp.manifest['converted_from']['channels']['s0']['unit'] == 'degC'


def test_bad_input_is_a_one_line_error(tmp_path, capsys):
    path = _occupancy_file(tmp_path)
    assert cli.main(['convert', 'room-occupancy', str(path), str(tmp_path / 'x'),
                     '--channels', 'S9_Light']) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'S9_Light' in err[0]
    assert cli.main(['convert', 'room-occupancy', str(tmp_path / 'none.csv'),
                     str(tmp_path / 'x')]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert cli.main(['convert', 'intel-lab', str(_intel_file(tmp_path)), str(tmp_path / 'x'),
                     '--motes', '40', '41']) == 2
    assert 'no epoch' in capsys.readouterr().err


def test_the_command_writes_a_readable_recording(tmp_path, capsys):
    path = _occupancy_file(tmp_path)
    assert cli.main(['convert', 'room-occupancy', str(path), str(tmp_path / 'room'),
                     '--min-length', '2', '--range', 'light', '0', '400']) == 0
    assert 'occupancy_2' in capsys.readouterr().out
    rec = load(tmp_path / 'room')
    assert rec.manifest['converted_from']['channels']['s0']['high'] == 400.0
    assert len(rec) == 40 and rec.manifest['source'] == 'hardware'


def test_too_few_complete_samples_say_how_many_there_are(tmp_path, capsys):
    """Mote 3 misses epoch 2 and night begins at epoch 4: motes 1-3 all report in runs of
    2, 1 and 2 epochs."""
    assert cli.main(['convert', 'intel-lab', str(_intel_file(tmp_path)), str(tmp_path / 'x'),
                     '--motes', '1', '2', '3', '--min-length', '3']) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'no run of 3 complete samples' in err[0], err
    assert 'the longest is 2' in err[0] and '--min-length' in err[0], err
