"""Section 2's synchrony analysis: correlations, intervals, statistics, command and figures."""
import json
import math

import numpy as np
import pytest

from khepera_noise_ros import cli, synchrony
from khepera_noise_ros.core.noise import NoiseModel
from khepera_noise_ros.recording import FORMAT, Recording, concatenate, write_csv
from khepera_noise_ros.testing.recordings import stationary


def series(x: np.ndarray, condition='c', episode_length=None, channels_used=None) -> Recording:
    """A recording of arbitrary (N, C) readings, one episode per ``episode_length`` rows."""
    n, c = x.shape
    length = episode_length or n
    manifest = {'format': FORMAT, 'source': 'hardware', 'sample_period_s': 0.5,
                'conditions': {condition: {}}}
    if channels_used is not None:
        manifest['channels_used'] = channels_used
    if c != 8:
        manifest['reading_range'] = [-1e6, 1e6]
    return Recording(np.arange(n) // length, np.arange(n) % length, np.full(n, np.nan),
                     np.full(n, condition), x, np.full(n, np.nan), np.full(n, np.nan), manifest)


def ar1(rng, n, phi, size=None):
    """Stationary AR(1) with unit variance."""
    shape = (n,) if size is None else (n, size)
    z = rng.standard_normal(shape) * math.sqrt(1 - phi ** 2)
    out = np.empty(shape)
    out[0] = rng.standard_normal(shape[1:])
    for t in range(1, n):
        out[t] = phi * out[t - 1] + z[t]
    return out


def test_fisher_interval_matches_the_textbook_formula():
    # r = 0.5, n = 28: z = atanh(0.5) = 0.5493, se = 1/5, 95% z-interval +-0.392
    low, high = synchrony.fisher_interval(0.5, 28)
    assert low == pytest.approx(math.tanh(0.549306 - 1.959964 / 5), abs=1e-5)
    assert high == pytest.approx(math.tanh(0.549306 + 1.959964 / 5), abs=1e-5)
    # centring 3 episodes costs 2 degrees of freedom
    assert synchrony.fisher_interval(0.5, 30, episodes=3) == pytest.approx((low, high))
    assert all(map(math.isnan, synchrony.fisher_interval(0.5, 3)))


def test_dependent_noise_is_synchronous_and_independent_is_not():
    """The paper's Figures 6-7: 8% dependent + 2% independent vs the reverse."""
    high = stationary(NoiseModel('combination', 0.08, 0.02), headings=(0.0,), steps=120,
                      condition='dependent')
    low = stationary(NoiseModel('combination', 0.02, 0.08), headings=(0.0,), steps=120,
                     condition='independent', first_episode=1, seed=2)
    # s1 and s4 read alike (mid-range) with the lamp ahead, as the paper's 100 and 110 do;
    # the facing pair s2, s3 sits at the light's floor, far below its group's average
    results = synchrony.analyse(concatenate([high, low]), pairs=[(1, 4), (1, 6)],
                                resamples=400)
    by = {r.condition: r for r in results}
    assert by['dependent'].pairs[0].r > 0.85
    assert by['independent'].pairs[0].r < 0.4
    for result in results:
        s2_s3, s1_s6 = result.pairs     # (s1, s4) in the first place
        assert s2_s3.bootstrap_ci[0] < s2_s3.r < s2_s3.bootstrap_ci[1]
        assert s2_s3.fisher_ci[0] < s2_s3.r < s2_s3.fisher_ci[1]
        assert abs(s1_s6.r) < 0.3          # s6 is in another dependence group
        assert result.samples == 120 and result.episodes == 1


def test_episodes_are_centred_so_headings_do_not_look_like_synchrony():
    """Independent noise at several headings: pooled raw readings correlate, fluctuations not."""
    rec = stationary(NoiseModel.independent_only(0.05), headings=(-40.0, 0.0, 40.0), steps=60)
    raw = np.corrcoef(rec.readings[:, 1], rec.readings[:, 4])[0, 1]
    (result,) = synchrony.analyse(rec, pairs=[(1, 4)], resamples=300)
    assert abs(raw) > 0.8
    assert abs(result.pairs[0].r) < 0.25
    assert result.episodes == 3


def test_block_bootstrap_widens_the_interval_for_autocorrelated_noise():
    """Fisher-z assumes independent samples; drift makes that interval too narrow."""
    rng = np.random.default_rng(4)
    n = 400

    def width(phi):
        shared = ar1(rng, n, phi)
        x = np.column_stack([shared + ar1(rng, n, phi), shared + ar1(rng, n, phi)])
        (res,) = synchrony.analyse(series(x), pairs=[(0, 1)], resamples=600, seed=1)
        p = res.pairs[0]
        return (p.bootstrap_ci[1] - p.bootstrap_ci[0]) / (p.fisher_ci[1] - p.fisher_ci[0]), \
            res.block_length
    white_ratio, white_block = width(0.0)
    drift_ratio, drift_block = width(0.9)
    assert 0.7 < white_ratio < 1.4
    assert drift_ratio > 1.6
    assert drift_block > white_block


def test_sensor_statistics_and_undefined_correlations():
    x = np.column_stack([np.tile([10.0, 12.0, 14.0, 12.0], 5), np.full(20, 7.0),
                         np.arange(20.0)])
    (res,) = synchrony.analyse(series(x), pairs=[(0, 1), (0, 2)], resamples=50)
    s0 = res.sensors[0]
    assert (s0.mean, s0.min, s0.max, s0.range) == (12.0, 10.0, 14.0, 4.0)
    assert s0.std == pytest.approx(np.std(x[:, 0], ddof=1))
    constant = res.pairs[0]
    assert math.isnan(constant.r) and all(map(math.isnan, constant.bootstrap_ci))
    assert res.to_dict()['pairs'][0]['r'] is None          # JSON has no NaN
    json.dumps(res.to_dict(), allow_nan=False)


def test_only_used_channels_are_analysed():
    rng = np.random.default_rng(0)
    x = rng.normal(100, 5, (50, 10))
    x[:, 3] = np.nan
    rec = series(x, channels_used=[0, 1, 2, 4, 5, 6, 7, 8, 9])
    (res,) = synchrony.analyse(rec, resamples=50)
    assert res.channels == [0, 1, 2, 4, 5, 6, 7, 8, 9] and res.matrix.shape == (9, 9)
    assert [p.sensors for p in res.pairs] == [(0, 1)]      # no s3, so not the Khepera pair
    with pytest.raises(ValueError, match=r'two different used channels .* got \[2, 3\]'):
        synchrony.analyse(rec, pairs=[(2, 3)])


def test_by_heading_splits_conditions():
    rec = stationary(headings=(0.0, 30.0), steps=20)
    labels = [r.condition for r in synchrony.analyse(rec, resamples=20, by_heading=True)]
    assert labels == ['bright @ 0 deg', 'bright @ 30 deg']


def test_command_writes_table_numbers_and_figures(tmp_path, capsys):
    parts = [stationary(NoiseModel('combination', d, 0.1 - d), headings=(0.0,), steps=40,
                        condition=c, first_episode=i, seed=i)
             for i, (c, d) in enumerate([('bulb_1ft', 0.01), ('bulb_2ft', 0.08),
                                         ('room_dark', 0.09)])]
    write_csv(concatenate(parts), tmp_path / 'rec')
    out = tmp_path / 'analysis'
    assert cli.main(['synchrony', str(tmp_path / 'rec.csv'), '--out', str(out),
                     '--pairs', '2,3', '0,5', '--resamples', '200']) == 0
    text = capsys.readouterr().out
    assert 'bulb_2ft' in text and 's0-s5' in text and '0.85' in text   # the paper's r
    data = json.loads((out / 'synchrony.json').read_text())
    assert [c['condition'] for c in data['conditions']] == ['bulb_1ft', 'bulb_2ft', 'room_dark']
    direct = synchrony.analyse(concatenate(parts), pairs=[(2, 3), (0, 5)], resamples=200)
    for saved, result in zip(data['conditions'], direct):
        assert saved['pairs'][0]['r'] == pytest.approx(result.pairs[0].r)
        assert saved['pairs'][0]['bootstrap_ci'] == pytest.approx(result.pairs[0].bootstrap_ci)
    rows = (out / 'synchrony.csv').read_text().splitlines()
    assert len(rows) == 1 + 3 * 2
    figures = sorted(p.name for p in out.glob('*.png'))
    assert figures == ['synchrony_bulb_s0_s5.png', 'synchrony_bulb_s2_s3.png',
                       'synchrony_matrix_bulb_1ft.png', 'synchrony_matrix_bulb_2ft.png',
                       'synchrony_matrix_room_dark.png', 'synchrony_other_s0_s5.png',
                       'synchrony_other_s2_s3.png']
    assert all((out / f).stat().st_size > 5000 for f in figures)


def test_command_reports_bad_input(tmp_path, capsys):
    write_csv(stationary(steps=10), tmp_path / 'rec')
    assert cli.main(['synchrony', str(tmp_path / 'rec'), '--pairs', '2,9']) == 2
    assert 'got [2, 9]' in capsys.readouterr().err
    assert cli.main(['synchrony', str(tmp_path / 'missing')]) == 2
    assert 'missing.csv: no such file' in capsys.readouterr().err
