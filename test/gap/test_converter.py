"""The sensor's converter in each sensor's value distribution (``gap.converter``): dropouts
marked and repaired, the limits the readings pile up at, and the value lattice, on
hand-made readings and in the statistics of simulated recordings.
"""
import numpy as np
import pytest

from khepera_noise_ros.effects import SaturationQuantization
from khepera_noise_ros.effects.base import Key
from khepera_noise_ros.effects.fitting import Z_DETECT
from khepera_noise_ros.gap import bootstrap, closedloop, converter, dropouts, stationary
from khepera_noise_ros.gap.families import of_part
from khepera_noise_ros.gap.protocol import kind
from khepera_noise_ros.gap.target import Repaired, Target
from khepera_noise_ros.testing.protocols import (CONFIG, closed_loop_protocol, dropped,
                                                 recorded, stationary_protocol)

ALL = tuple(range(8))
LATTICE = SaturationQuantization(ALL, step=4.0)


def _runs(n, length):
    return np.split(np.arange(n), np.arange(length, n, length))


def _marks(x, runs, moving=False):
    return dropouts.repair(x, dropouts.Runs(runs, len(x)), moving)[1]


# -- dropouts on hand-made readings -------------------------------------------------------

def test_isolated_extremes_are_marked_and_repaired_and_nothing_else():
    rng = np.random.default_rng(3)
    clean = np.round(400 + 8 * rng.standard_normal((6000, 3)))
    x = clean.copy()
    lost = rng.random(6000) < 0.02
    x[lost, 0] = 0.0                                     # to zero
    x[lost, 1] = 1023.0                                  # to the top of a 10-bit scale
    x[lost & (np.arange(6000) % 2 == 0), 1] = 0.0        # ... or to zero
    runs = _runs(6000, 300)
    repaired, marks, ends = dropouts.repair(x, dropouts.Runs(runs, len(x)))
    assert marks[:, 0, 0].sum() >= 0.95 * lost.sum()     # pairs next to each other too
    assert np.array_equal(marks[:, 0, 0] > 0, lost & (marks[:, 0, 0] > 0))
    assert marks[:, 1, :].sum() >= 0.95 * lost.sum()
    assert marks[:, 1, 1].sum() > 0 and marks[:, 1, 0].sum() > 0
    assert ends[1].tolist() == [0.0, 1023.0]
    assert marks[:, 2].sum() == 0                        # clean: nothing
    assert _marks(clean, runs).sum() == 0
    # repaired readings lie at the level of their neighbours, not at the extreme
    hit = marks[:, 0, 0] > 0
    assert np.all(np.abs(repaired[hit, 0] - 400) < 60)


def test_a_ceiling_and_a_sweeping_light_are_not_dropouts():
    rng = np.random.default_rng(4)
    noise = np.round(400 + 8 * rng.standard_normal((6000, 3)))
    ceiling = np.minimum(noise, 405.0)                    # a limit: a pile, not isolated
    t = np.arange(6000) % 300
    sweep = np.round(np.clip(500 - 500 * np.exp(-0.5 * ((t - 150) / 3.0) ** 2)
                             + 3 * rng.standard_normal(6000), 50, 525))   # a lamp passes
    x = np.stack([ceiling[:, 0], sweep, noise[:, 2]], axis=1)
    assert (x[:, 1] == 50).sum() > 20
    for moving in (False, True):
        assert _marks(x, _runs(6000, 300), moving).sum() == 0


def test_a_limit_the_light_reaches_is_a_dropout_value_only_where_the_light_is_steady():
    """A lamp holds the sensor at its saturation (50) for whole runs; elsewhere single
    readings read 50.  While the light moves (closed loop) a quick turn can point the
    sensor at the lamp for one step: not a dropout.  In a stationary run the light is
    steady: a lone 50 in a run at 150 is one."""
    rng = np.random.default_rng(5)
    visit = np.round(150 + 3 * rng.standard_normal(6000))
    visit[:1500] = 50.0
    lone = np.arange(1650, 6000, 300)
    visit[lone] = 50.0
    x = visit[:, None]
    assert _marks(x, _runs(6000, 300), moving=True).sum() == 0
    marks = _marks(x, _runs(6000, 300), moving=False)
    assert np.array_equal(np.flatnonzero(marks[:, 0, 0]), lone)


def test_dropouts_to_a_value_apart_from_every_other_reading_are_marked():
    """A dark sensor (level 500, noise of +-10) whose light also moves: lost readings at
    525 lie within six robust sds of the level and beside neighbours that move, but the
    value stands apart from every reading the sensor gave otherwise.  Readings on a coarse
    lattice, or a clean sensor, get no marks."""
    rng = np.random.default_rng(8)
    n = 6000
    t = np.arange(n)
    light = 500 - 250 * np.clip(np.sin(t / 7.0), 0, None) ** 4        # a lamp passing
    clean = np.round(light[:, None] + rng.uniform(-10, 10, (n, 3)))
    x = clean.copy()
    lost = rng.random(n) < 0.02
    x[lost, 0] = 525.0
    x[:, 2] = np.round(clean[:, 1] / 16) * 16                          # a lattice
    runs = np.split(t, np.arange(60, n, 60))
    marks = _marks(x, runs, moving=True)
    assert marks[:, 0, 1].sum() >= 0.9 * lost.sum()
    assert np.all(lost[marks[:, 0, 1] > 0])
    assert marks[:, 1:].sum() == 0
    assert _marks(clean, runs, moving=True).sum() == 0


def test_readings_flanked_by_their_own_value_are_never_dropouts():
    rng = np.random.default_rng(4)
    seen = 0
    for _ in range(20):
        n = 400
        col = np.clip(np.round(rng.normal(530, 30, n)), 0, 525)
        col[rng.random(n) < 0.03] = 0.0
        runs = _runs(n, n // 4)
        marks = _marks(col[:, None], runs)[:, 0]
        for r in runs:
            x, m = col[r], marks[r]
            flanked = np.r_[False, (x[:-2] == x[1:-1]) & (x[2:] == x[1:-1]), False]
            assert not (m.any(axis=1) & flanked).any()
            seen += int(flanked.sum())
        assert marks[:, 0].sum() > 0                  # the lone zeros are dropouts
    assert seen > 0                                   # clipped stretches at 525 exist


# -- dropouts in recordings ---------------------------------------------------------------

def test_dropout_statistics_see_the_dropouts_and_the_others_do_not():
    rec = recorded(stationary_protocol(samples=60), seed=5)
    lossy = dropped(rec, (3,), 0.02, 0.0)
    clean_stats, lossy_stats = (Target([r], CONFIG, replicates=0).real for r in (rec, lossy))
    index = clean_stats.index
    key = Key('dropout', (3,), None, dropouts.ENDS[0])
    assert clean_stats.estimate[index[key]] == 0.0
    assert lossy_stats.estimate[lossy_stats.index[key]] == pytest.approx(0.02, abs=0.008)
    spreads = [k for k in clean_stats.keys if k.family == 'spread' and k.sensors == (3,)]
    a = np.array([clean_stats.estimate[index[k]] for k in spreads])
    b = np.array([lossy_stats.estimate[lossy_stats.index[k]] for k in spreads])
    assert np.max(np.abs(b - a) / (a + 1)) < 0.2     # without the repair: tens of times
    assert not any(k.family == 'dropout' and lossy_stats.estimate[i] > 0
                   for i, k in enumerate(lossy_stats.keys) if k.sensors == (5,))


def test_the_fit_counts_dropouts_in_closed_loop_recordings_against_the_simulator():
    closed = recorded(closed_loop_protocol(24), seed=6)
    target = Target([dropped(closed, ALL, 0.01, 0.0)], CONFIG, seed=1, replicates=0)
    lost = dropouts.dropouts(target.real_data, target.simulate())
    assert len(lost) >= 4
    assert {v for v, _ in lost.values()} == {0.0}
    clean = Target([closed], CONFIG, seed=1, replicates=0)
    assert dropouts.dropouts(clean.real_data, clean.simulate()) == {}


def test_a_repaired_recording_keeps_its_marks_and_extremes():
    real = dropped(recorded(stationary_protocol(samples=60), seed=5), (3,), 0.02, 0.0)
    prepared = Repaired.of(real)
    assert prepared.recording is not real and prepared.kind == 'stationary'
    assert prepared.marks[:, 3, 0].sum() > 0 and prepared.ends[3, 0] == 0.0
    assert prepared.recording.readings[:, 3].min() > 0                 # repaired
    assert real.readings[:, 3].min() == 0.0                            # the original kept
    assert kind(prepared.recording) == 'stationary'
    clean = recorded(stationary_protocol(samples=12), seed=5)
    assert Repaired.of(clean).recording.readings is clean.readings     # nothing to repair


# -- limits --------------------------------------------------------------------------------

def test_the_limit_detector_on_hand_made_readings():
    """A clip at the top 3% of normal readings is found (pooled over the sensors sharing
    it); narrower noise, a value lattice and a limit of the reading range are not."""
    rng = np.random.default_rng(3)
    sim = np.round(400 + 10 * rng.standard_normal((6000, 4)))
    real = np.round(400 + 10 * rng.standard_normal((2000, 4)))
    ceiling = float(np.quantile(real[:, 0], 0.97).round())
    clipped = real.copy()
    clipped[:, :2] = np.minimum(clipped[:, :2], ceiling)
    clipped[:, 2] = np.round(400 + 6 * rng.standard_normal(2000))          # narrower
    clipped[:, 3] = np.round(real[:, 3] / 4) * 4                           # a lattice
    found = converter.limits(clipped, sim, range(4), (0.0, 525.0))
    assert [(f['end'], f['value'], f['sensors']) for f in found] == [(1, ceiling, (0, 1))]
    assert 0.02 < found[0]['share'] < 0.06
    assert converter.limits(clipped, sim, range(4), (0.0, ceiling)) == []     # the range's
    assert converter.limits(real, sim, range(4), (0.0, 525.0)) == []


def test_a_lattice_of_readings_converted_from_another_unit_is_measured():
    """Readings mapped from another unit are not whole: whole lux onto 0..525 lie on a
    lattice of 525/280, 1/16 degree printed to 2 decimals on one of about 7.2 to a tenth
    of a step; readings with no lattice, one no coarser than 1, or a few values far apart
    (a step over 32) have none."""
    rng = np.random.default_rng(5)
    lux = np.round(np.clip(rng.normal(40, 30, 4000), 0, 280))
    assert converter.grid(525 * (280 - lux) / 280) == (1.875, 0.0)
    celsius = np.round(np.round(rng.normal(26, 0.8, 4000) * 16) / 16, 2)
    step, origin = converter.grid(525 * (29 - celsius) / (29 - 24.44))
    assert abs(step - 525 / 16 / 4.56) < 0.05 * step, step
    assert converter.on_grid(525 * (29 - celsius) / (29 - 24.44), step, origin) > 0.95
    shifted = np.round(rng.normal(300, 20, 4000) / 7.3) * 7.3 + 1.1
    assert converter.grid(shifted) == (7.3, 1.1)
    for plain in (rng.normal(300, 5, 4000), np.round(rng.normal(300, 5, 4000) * 2) / 2,
                  rng.uniform(0, 525, 4000), np.repeat([100.3, 250.7, 400.1], 10)):
        assert converter.grid(plain) == (1, 0)
    assert converter.grid(np.round(rng.normal(300, 30, 4000) / 16) * 16) == (16, 0)


def test_the_fitter_rounds_converted_readings_onto_the_lattice_most_sensors_share():
    """Four sensors on the lattice of whole lux, three on another: the effect takes the
    first and only the sensors on it (one step rounds them all)."""
    rec = recorded(stationary_protocol(samples=60), seed=21)
    readings = rec.readings.copy()
    readings[:, :4] = np.round(readings[:, :4] / 1.875) * 1.875
    readings[:, 4:7] = np.round((readings[:, 4:7] - 1.1) / 7.3) * 7.3 + 1.1
    rec = dropped(rec, [], 0.0, 0.0)
    rec.readings[:] = readings
    target = Target([rec], CONFIG, replicates=60)
    c = target.compare()
    found = target.evidence(c).converter()['lattices']
    assert found == {**{s: (1.875, 0.0) for s in range(4)}, **{s: (7.3, 1.1) for s in (4, 5, 6)}}
    cand = SaturationQuantization.fit(target.evidence(c))
    assert cand.effect is not None and (cand.effect.step, cand.effect.origin) == (1.875, 0.0)
    assert set(cand.effect.sensors) >= {0, 1, 2, 3}
    assert not set(cand.effect.sensors) & {4, 5, 6}, cand


# -- the value lattice in closed loop ---------------------------------------------------------

def _shares(stats, q):
    return {k.sensors[0]: stats.estimate[stats.index[k]] for k in stats.keys
            if k.family == 'loop_granularity' and k.part == f'step {q}'}


def test_a_lattice_shows_in_closed_loop_readings():
    """Readings on multiples of 4: every value a sensor takes inside its range lies on
    one residue modulo 2 and 4; a clean recording's values spread over the residues."""
    for effects, expect in (([LATTICE], 1.0), ([], None)):
        rec = recorded(closed_loop_protocol(24), effects, seed=11)
        stats = Target([rec], CONFIG, replicates=0).real
        for q in (2, 4):
            share = _shares(stats, q)
            assert len(share) == 8, share
            for v in share.values():
                if expect is None:
                    assert v < 1.0 / q + 0.2, (q, share)
                else:
                    assert v == expect, (q, share)


def test_value_statistics_only_without_a_stationary_part():
    """Beside a stationary recording (which has its own granularity) they are not added."""
    closed = recorded(closed_loop_protocol(8), seed=12)
    stationary = recorded(stationary_protocol(), seed=12)
    alone = Target([closed], CONFIG, 1, replicates=20)
    both = Target([stationary, closed], CONFIG, 1, replicates=20)
    assert any(k.family == 'loop_granularity' for k in alone.real.keys)
    assert not any(k.family == 'loop_granularity' for k in both.real.keys)
    marks = np.zeros(closed.readings.shape + (2,))
    b = closedloop.blocks(closed, closed.readings, lambda order, ep, m: converter.loop_sums(
        closed.readings[order], marks[order], ep, m, False), CONFIG.task.perturb_every)
    with np.errstate(invalid='ignore', divide='ignore'):      # as ``Target`` computes them
        keys, _ = closedloop.stats(b, bootstrap.resampled(b, 0, 0), converter.loop_stats)
    assert not {k.family for k in keys} & of_part('loop_values')
    assert 'closed_loop_dropout' in {k.family for k in keys}


def test_a_value_held_is_not_a_lattice():
    """A sensor parked at one reading (the light model's brightest, a robot at the lamp)
    for most samples: each value counts once, so the residue share stays near 1/q."""
    rng = np.random.default_rng(3)
    r = np.where(rng.random((3000, 8)) < 0.8, 50.0, rng.integers(40, 400, (3000, 8)))
    q2 = converter.MODULI.index(2)

    def shares(x):
        sums = converter.loop_sums(x, np.zeros(x.shape + (2,)), np.zeros(len(x), int), 1, True)
        return sums['lv_residue'][0] / sums['lv_weight'][0][:, None]
    assert np.all(shares(r)[:, q2] < 0.6), shares(r)[:, q2]
    # the same readings every one on a multiple of 2 are a lattice
    assert np.all(shares(2 * np.round(r / 2))[:, q2] == 1.0)


def test_a_clean_closed_loop_recording_shows_no_lattice():
    """Real against simulated, no effect: no granularity statistic is off."""
    rec = recorded(closed_loop_protocol(24), seed=13)
    target = Target([rec], CONFIG, 1, replicates=60)
    c = target.compare()
    z = [abs(z) for k, z in zip(c.keys, c.z) if k.family == 'loop_granularity']
    assert len(z) == 8 * len(converter.MODULI)
    assert max(z) < 4.0, max(z)
    assert SaturationQuantization.fit(target.evidence(c)).effect is None


def test_the_saturation_fitter_reads_the_closed_loop_lattice():
    rec = recorded(closed_loop_protocol(24), [LATTICE], seed=14)
    target = Target([rec], CONFIG, 1, replicates=60)
    c = target.compare()
    flagged = {k.sensors[0] for k, z in zip(c.keys, c.z)
               if k.family == 'loop_granularity' and z > Z_DETECT}
    assert flagged == set(range(8)), flagged
    cand = SaturationQuantization.fit(target.evidence(c))
    assert cand.effect is not None and cand.effect.step == 4.0, cand


# -- the converter's sums, from histograms of whole readings ---------------------------

def _residue_plain(x: np.ndarray) -> np.ndarray:
    """(N, C, moduli) 1 where a reading lies on its channel's most common residue."""
    out = np.zeros(x.shape + (len(converter.MODULI),))
    for k in range(x.shape[1]):
        for j, q in enumerate(converter.MODULI):
            r = np.mod(x[:, k].astype(np.int64), q)
            out[:, k, j] = r == np.bincount(r, minlength=q).argmax()
    return out


def _mode_plain(x: np.ndarray, cell: np.ndarray) -> np.ndarray:
    out = np.zeros(x.shape)
    for c in np.unique(cell):
        at = cell == c
        for k in range(x.shape[1]):
            values, counts = np.unique(x[at, k], return_counts=True)
            out[at, k] = x[at, k] == values[np.argmax(counts)]
    return out


@pytest.mark.parametrize('samples,length', [(20, 5), (40, 150)])
def test_mode_residue_and_pile_counts_equal_reading_by_reading_counts(samples, length):
    rec = recorded(stationary_protocol(samples=samples), [SaturationQuantization(
        (0, 1, 2, 3), step=4.0, origin=1.0)])
    lay = stationary.Layout(rec, length)
    x = rec.readings.astype(np.float64)
    marks = np.zeros(x.shape + (2,))
    sums = converter.stationary_sums(x, marks, lay.cell, lay.order, lay.by_block)
    o, by = lay.order, lay.by_block
    assert np.array_equal(sums['residue'], by(_residue_plain(x)[o]))
    assert np.array_equal(sums['at_mode'], by(_mode_plain(x, lay.cell)[o]))
    assert np.array_equal(sums['edge'], by(converter.edge_hits(x)[o]))
    on_lattice = sums['residue'][:, :4, converter.MODULI.index(4)].sum()
    assert on_lattice > 0.9 * 4 * len(rec)          # the quantised sensors sit on it


def _integer_columns(rng) -> np.ndarray:
    n, c = int(rng.integers(1, 400)), int(rng.integers(1, 5))
    centre = rng.choice([0.0, 50.0, 500.0, 1023.0])
    x = np.round(rng.normal(centre, rng.choice([0.3, 2.0, 15.0, 200.0]), (n, c)))
    if rng.random() < 0.4:          # a floor or ceiling holding some readings
        x = np.clip(x, np.round(np.quantile(x, rng.random() * 0.2)), None)
    if rng.random() < 0.3:          # a few strays far out
        x[rng.integers(0, n, 3), rng.integers(0, c)] = rng.choice([0.0, 1023.0, 5e5])
    return x


def test_pile_ends_from_the_histogram_are_the_edge_hits_of_every_sample():
    rng = np.random.default_rng(7)
    spread_out = 0
    for _ in range(300):
        x = _integer_columns(rng)
        spread_out += int(np.ptp(x) >= 1e5)        # over 1e5 values: the per-sample way
        n = len(x)
        whole = stationary.Grouping(np.zeros(n, np.int64), 1, np.zeros(1, np.int64),
                                    np.zeros(1, np.int64))       # every sample in one group
        sums = converter.stationary_sums(x, np.zeros(x.shape + (2,)), np.zeros(n, int),
                                         np.arange(n), whole)
        assert np.array_equal(sums['edge'][0], converter.edge_hits(x).sum(axis=0))
    assert spread_out > 0


def test_rare_counts_are_the_marks_of_the_channels_used():
    rec = recorded(stationary_protocol(samples=13),
                   [SaturationQuantization((1, 4, 6), dropout=0.03)])
    rec.manifest = dict(rec.manifest, channels_used=[6, 1, 4, 0])
    ready = Repaired.of(rec)
    marks = ready.marks
    assert marks[:, [1, 4, 6]].sum() > 10
    counts = dropouts.counts([ready])
    hits = np.count_nonzero(marks[:, [6, 1, 4, 0]], axis=0)
    for k, sensor in enumerate([6, 1, 4, 0]):
        for end, name in enumerate(dropouts.ENDS):
            assert counts[Key('dropout', (sensor,), None, name)] == \
                [float(hits[k, end]), float(len(rec))]
    pooled = counts[Key('dropout', (6, 1, 4, 0), None, dropouts.ENDS[0])]
    assert pooled == [float(hits[:, 0].sum()), 4.0 * len(rec)]
