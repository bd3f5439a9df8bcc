"""The pure conversions behind the ROS-native view: sensor frames, cmd_vel turns,
illuminance and its variance; no rclpy."""
import math

import numpy as np
import pytest

from khepera_noise_ros.core.frames import BASE_FRAME, sensor_frame, sensor_poses
from khepera_noise_ros.core.illuminance import (QUANTISATION, draw_variance, illuminance,
                                                illuminance_variance, reading_variance)
from khepera_noise_ros.core.khepera import DARK, SENSOR_ANGLES_DEG, World
from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.core.twist import MAX_POWER, rad_per_power, turn_for, yaw_rate


def test_sensor_frames_sit_on_the_rim_facing_out_in_rep103_terms():
    poses = sensor_poses('r1/')
    assert BASE_FRAME == 'base_link'
    assert [p.frame for p in poses] == [f'r1/light_sensor_{n}' for n in range(8)]
    left, front_left = poses[0], poses[2]
    assert left.y > 0 and abs(left.x) < 1e-12          # s0 looks left: +y in REP 103
    assert poses[5].y < 0                                # s5 looks right
    assert poses[6].x < 0 and poses[7].x < 0             # s6, s7 at the back
    assert front_left.x > 0 and front_left.y > 0
    for pose, deg in zip(poses, SENSOR_ANGLES_DEG):
        assert math.hypot(pose.x, pose.y) == pytest.approx(0.0275)
        qx, qy, qz, qw = pose.quaternion
        assert math.degrees(2 * math.atan2(qz, qw)) == pytest.approx(deg)
        assert qz * qz + qw * qw == pytest.approx(1.0)


def test_a_sensor_frame_outside_0_to_7_is_refused():
    with pytest.raises(ValueError, match='sensor must be 0..7, got 8'):
        sensor_frame(8)


def test_a_counter_clockwise_yaw_rate_is_a_left_turn_and_maps_back():
    unit = rad_per_power(3.0, 10.0)
    assert unit == pytest.approx(math.radians(30.0))
    for direction in (-1, 1):
        for power in range(MAX_POWER + 1):
            rate = yaw_rate(direction, power, 3.0, 10.0)
            turn = turn_for(rate, 3.0, 10.0)
            assert turn.power == power and not turn.clipped
            if power:
                assert turn.direction == direction
                assert (rate > 0) == (direction == -1)     # left = CCW = positive


def test_a_rate_beyond_power_9_is_clipped_and_said_so():
    turn = turn_for(-100.0, 3.0, 10.0)
    assert turn == (1, MAX_POWER, True)
    assert turn_for(0.0, 3.0, 10.0) == (1, 0, False)


@pytest.mark.parametrize('bad', [math.nan, math.inf, -math.inf, '1'])
def test_a_rate_that_is_not_a_finite_number_is_refused(bad):
    with pytest.raises(ValueError, match='angular.z must be a finite yaw rate'):
        turn_for(bad, 3.0, 10.0)


def test_illuminance_grows_with_light_and_scales_with_lux_per_count():
    readings = np.array([DARK, 500.0, 50.0, 0.0])
    assert illuminance(readings).tolist() == [0.0, 25.0, 475.0, 525.0]
    assert illuminance(readings, 2.0).tolist() == [0.0, 50.0, 950.0, 1050.0]


def test_the_variance_of_a_truncated_uniform_draw_is_exact():
    """getnoise on half-width 2.5: |draw| is 0 with chance .4, 1 with .4, 2 with .2."""
    assert draw_variance(2.5, 'uniform') == pytest.approx(0.4 * 1 + 0.2 * 4)
    assert draw_variance(0.0, 'uniform') == 0.0 and draw_variance(0.0, 'normal') == 0.0
    # for large draws truncation hardly matters: (p v)^2 / 3
    assert draw_variance(1000.0, 'normal') == pytest.approx(1000.0 ** 2 / 3, rel=2e-3)


def test_variance_follows_the_model_parts():
    readings = np.array([100.0, 200, 300, 400, 500, 100, 300, 500])
    indep = NoiseModel.independent_only(0.1)
    assert reading_variance(readings, indep) == pytest.approx(
        draw_variance(0.1 * readings, 'uniform') + QUANTISATION)
    comb = NoiseModel(dependent=0.05, independent=0.0, groups=((0, 1), (6, 7)))
    expected = np.full(8, QUANTISATION)
    expected[[0, 1]] += draw_variance(0.05 * 150.0, 'uniform')
    expected[[6, 7]] += draw_variance(0.05 * 400.0, 'uniform')
    assert reading_variance(readings, comb) == pytest.approx(expected)
    none = NoiseModel(model='none')
    assert reading_variance(readings, none) == pytest.approx(np.full(8, QUANTISATION))
    assert illuminance_variance(readings, None).tolist() == [0.0] * 8      # unknown
    assert illuminance_variance(readings, comb, 2.0) == pytest.approx(4 * expected)


@pytest.mark.parametrize('distribution', ['uniform', 'normal'])
def test_variance_matches_the_spread_of_sampled_readings(distribution):
    """Drawn readings around a base (kept off the clip at 525) spread as
    reading_variance says."""
    base = np.rint(World(ambient=400.0).light_table()[:, 300])   # lamp 30 deg to the left
    noise = NoiseModel(dependent=0.08, independent=0.06, distribution=distribution)
    samples = noise.sample(base, np.random.default_rng(1), samples=40000)
    measured = samples.var(axis=0)
    predicted = reading_variance(base, noise) - QUANTISATION
    assert measured == pytest.approx(predicted, rel=0.03)


def test_the_conversions_are_pure():
    """The modules behind the ROS conventions import no rclpy and no message types."""
    import subprocess
    import sys
    code = ('import sys; import khepera_noise_ros.core.frames, khepera_noise_ros.core.twist, '
            'khepera_noise_ros.core.illuminance; '
            'print(sorted(m for m in sys.modules if m.startswith(("rclpy", "sensor_msgs", '
            '"geometry_msgs", "std_msgs"))))')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == '[]'
