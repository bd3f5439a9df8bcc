"""Property tests: the fitters never crash the diagnosis and never give an effect that cannot
run, whatever the (valid) recording."""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from khepera_noise_ros import effects as fx
from khepera_noise_ros.effects import NAMES, REGISTRY, TemporalDrift
from khepera_noise_ros.effects.simulate import EffectEpisodes
from khepera_noise_ros import simconfig
from khepera_noise_ros.experiment import diagnosis_report as report
from khepera_noise_ros.gap import diagnose
from khepera_noise_ros.gap.select import fit_one, runnable
from khepera_noise_ros.gap.target import Target
from khepera_noise_ros.testing.protocols import CONFIG, stationary_protocol

SHAPES = ('white', 'affine', 'bright', 'walk', 'clip', 'steps', 'dropout')


def _readings(rec, shape: str, scale: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    n = len(rec)
    base = rng.uniform(20, 500, 8)[None, :] + 0 * rec.readings
    noise = rng.standard_normal((n, 8))
    if shape == 'affine':                       # every sensor's spread affine in its level
        noise *= scale * (1.0 + base / 50.0)
    elif shape == 'bright':
        noise *= scale * (525.0 - base) / 50.0
    elif shape == 'walk':
        noise = scale * np.cumsum(noise, axis=0) / 5.0
    else:
        noise *= scale
    x = base + noise
    if shape == 'clip':
        x = np.minimum(x, np.quantile(x, 0.9))
    if shape == 'steps':
        x = np.round(x / 8.0) * 8.0
    if shape == 'dropout':
        x[rng.random(x.shape) < 0.02] = 0.0
    return np.clip(np.rint(x), 0, 525)


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(shape=st.sampled_from(SHAPES), scale=st.floats(0.0, 30.0), seed=st.integers(0, 2 ** 16))
def test_every_fitter_returns_a_runnable_effect_or_a_reason(shape, scale, seed):
    rec = stationary_protocol(samples=12, repeats=2)
    rec.readings = _readings(rec, shape, scale, seed)
    rec.manifest = dict(rec.manifest, source='emulator')
    try:
        diagnose.check([rec])
    except ValueError:
        return                                   # refused with a one-line error: fine
    target = Target([rec], CONFIG, seed, replicates=20)
    c = target.compare()
    for name in NAMES:
        cand = fit_one(name, target, c)
        assert cand.name == name and cand.note
        if cand.effect is not None:
            runnable(cand.effect)
            assert fx.from_dict(cand.effect.to_dict()) == cand.effect


def test_a_fitter_that_raises_is_reported_as_not_fitting(monkeypatch):
    rec = stationary_protocol(samples=12)
    rec.readings = _readings(rec, 'white', 3.0, 1)
    target = Target([rec], CONFIG, 0, replicates=20)

    class Broken(TemporalDrift):
        @classmethod
        def fit(cls, evidence):
            raise ZeroDivisionError('float division by zero')
    monkeypatch.setitem(REGISTRY, 'temporal_drift', Broken)
    cand = fit_one('temporal_drift', target, target.compare())
    assert cand.effect is None and 'ZeroDivisionError' in cand.note


def test_a_drift_with_time_constant_zero_is_refused_not_run():
    with pytest.raises(ValueError, match='time_constant'):
        runnable(TemporalDrift((0,), 0.01, 0.0, True))


def test_affine_spread_on_every_sensor_is_diagnosed_without_a_traceback(tmp_path):
    """The recording that once ended in ZeroDivisionError (a drift fitted with time
    constant 0): every sensor's spread affine in its level.  The whole diagnosis runs,
    and what it writes loads back as simulator parameters."""
    rec = stationary_protocol(samples=20, repeats=2)
    rec.readings = _readings(rec, 'affine', 2.0, 7)
    rec.manifest = dict(rec.manifest, source='emulator')
    result = diagnose.diagnose([rec], diagnose.Options(config=CONFIG, replicates=30))
    paths = report.write(result, tmp_path, CONFIG, figures=False)
    for key in ('params', 'params_with_remainder'):
        if key in paths:
            loaded = simconfig.load(paths[key])
            assert len(loaded.effects) >= 1
            EffectEpisodes(effects=loaded.effects).reset(np.arange(2))
