"""The record command's protocols that identify the simulator's world: the heading sweep and
the turn calibration, driving a robot node over the lockstep topics."""
import numpy as np
import pytest

from khepera_noise_ros import cli
from khepera_noise_ros.commands import record as record_command
from khepera_noise_ros.commands._options import UsageError
from khepera_noise_ros.recording import load, write_csv


def parse(*argv):
    return cli.build_parser().parse_args(['record', *map(str, argv)])


def test_the_sweep_goes_round_the_circle_twice_where_the_lamp_is_on(ros_context, tmp_path):
    args = parse(tmp_path / 's', '--protocol', 'sweep', '--conditions', 'bulb_1ft,room_dark',
                 '--sweep-step', 90, '--samples', 3)
    rec, _ = record_command.record(args, context=ros_context)
    lit = [float(rec.heading_deg[rec.episode == e][0]) for e in np.unique(rec.episode)
           if rec.condition[rec.episode == e][0] == 'bulb_1ft']
    assert lit == [-180.0, -90.0, 0.0, 90.0, 90.0, 0.0, -90.0, -180.0]
    assert (rec.heading_deg[rec.condition == 'room_dark'] == 0).all()
    assert len(np.unique(rec.episode)) == 10 and len(rec) == 30
    assert rec.manifest['sweep_step_deg'] == 90 and rec.manifest['sweep_passes'] == 2
    write_csv(rec, tmp_path / 's')
    assert load(tmp_path / 's').manifest['protocol'] == 'stationary'


def test_the_turn_calibration_turns_each_power_both_ways_between_rests(ros_context, tmp_path):
    args = parse(tmp_path / 't', '--protocol', 'turns', '--turn-repeats', 1,
                 '--turn-rest', 10)
    rec, _ = record_command.record(args, context=ros_context)
    assert rec.manifest['calibration'] == 'turns' and rec.conditions() == ['turns_task']
    assert rec.manifest['task']['perturbation_deg'] == 0.0
    assert len(np.unique(rec.episode)) == 9 and len(rec) == 9 * 50
    for power in range(1, 10):
        ep = rec.select(rec.episode == power - 1)
        turned = np.flatnonzero(ep.power > 0)
        assert ep.step[turned].tolist() == [9, 19, 29, 39]
        assert ep.direction[turned].tolist() == [1, -1, 1, -1]
        assert (ep.power[turned] == power).all()
        assert ep.heading_deg[0] == pytest.approx(-1.5 * power)
        # the simulator reports its bearing: each turn moves it by the command
        made = (ep.heading_deg[turned + 1] - ep.heading_deg[turned] + 180) % 360 - 180
        np.testing.assert_allclose(made, 3.0 * power * ep.direction[turned])
    write_csv(rec, tmp_path / 't')
    assert load(tmp_path / 't').manifest['calibration'] == 'turns'


@pytest.mark.parametrize('option, value, message', [
    ('--turn-rest', 5, '--turn-rest must be >= 10'),
    ('--sweep-step', 0, '--sweep-step must be in'),
    ('--sweep-passes', 0, '--sweep-passes must be >= 1')])
def test_bad_protocol_options_are_one_line(option, value, message, tmp_path):
    with pytest.raises(UsageError, match=message) as info:
        record_command.run(parse(tmp_path / 'x', '--protocol', 'sweep', option, value))
    assert '\n' not in str(info.value)
