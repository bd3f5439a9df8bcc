"""Property tests (hypothesis) of the file readers: recordings (CSV, YAML manifest, MCAP
bag) and settings (replicate config, emulator effects, the simulator's fitted parameters).
Any content either loads to a valid value or is refused with a one-line reason of the
project's own error type (ValueError and its kinds, FileNotFoundError), never another
exception."""
from __future__ import annotations

import dataclasses
import json
import os
import shutil
import tempfile
from pathlib import Path

import yaml
from hypothesis import HealthCheck, given, settings, strategies as st

from khepera_noise_ros import recording
from khepera_noise_ros.bag import read_bag, write_bag
from khepera_noise_ros.experiment import config as replicate_config
from khepera_noise_ros import simconfig
from khepera_noise_ros import effects as fx
from khepera_noise_ros.nodes.checkpoint import FORMAT as CHECKPOINT, Checkpoint
from khepera_noise_ros.reality.effects import EFFECTS, EffectsConfig
from khepera_noise_ros.testing.recordings import sample_recording

# examples per test: a few dozen in the suite (files make them slow); set
# KHEPERA_NOISE_EXAMPLES=200 for the thorough run docs/robustness.md reports
EXAMPLES = int(os.environ.get('KHEPERA_NOISE_EXAMPLES', '40'))
SETTINGS = settings(max_examples=EXAMPLES, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])
REFUSALS = (ValueError, FileNotFoundError)      # RecordingError, ProtocolError are ValueErrors


def loads_or_refuses(load, *args):
    try:
        return load(*args)
    except Exception as exc:        # noqa: BLE001 - the property is about its type
        assert isinstance(exc, REFUSALS), f'{type(exc).__name__}: {exc}'
        assert str(exc) and '\n' not in str(exc), repr(str(exc))
        return None


WORK = Path(tempfile.mkdtemp(prefix='khepera-properties-'))
REC = sample_recording()
CSV, MANIFEST = (p.read_bytes() for p in recording.write_csv(REC, WORK / 'valid'))
BAG = write_bag(REC, WORK / 'valid_bag')


def damaged(data, original: bytes, most: int = 6) -> bytes:
    """``original`` with a few bytes flipped, replaced, cut off or inserted."""
    raw = bytearray(original)
    for _ in range(data.draw(st.integers(1, most))):
        how = data.draw(st.sampled_from(['flip', 'byte', 'cut', 'insert', 'line']))
        at = data.draw(st.integers(0, max(len(raw) - 1, 0)))
        if how == 'flip' and raw:
            raw[at] ^= 1 << data.draw(st.integers(0, 7))
        elif how == 'byte' and raw:
            raw[at] = data.draw(st.sampled_from(b',\n\r:-.e0x"\'{}[]#& \xff\x00'))
        elif how == 'cut':
            del raw[at:]
        elif how == 'insert':
            raw[at:at] = data.draw(st.binary(min_size=1, max_size=12))
        else:
            raw[at:at] = data.draw(st.sampled_from([b'\n', b'nan', b'inf', b'-1', b'1e308',
                                                    b'9' * 30, b',,', b'- ', b': ']))
    return bytes(raw)


def written(name: str, content: bytes) -> Path:
    path = Path(tempfile.mkdtemp(dir=WORK)) / name
    path.write_bytes(content)
    return path


def check_recording(rec) -> None:
    if rec is not None:
        rec.check()                         # a loaded recording keeps the format
        assert len(rec) == rec.readings.shape[0] == rec.step.size


# -- recordings ---------------------------------------------------------------------------

@SETTINGS
@given(data=st.data(), which=st.sampled_from(['csv', 'yaml', 'both']))
def test_a_damaged_csv_recording_loads_or_is_refused(data, which):
    csv_bytes = damaged(data, CSV) if which in ('csv', 'both') else CSV
    yaml_bytes = damaged(data, MANIFEST) if which in ('yaml', 'both') else MANIFEST
    folder = written('rec.csv', csv_bytes).parent
    (folder / 'rec.yaml').write_bytes(yaml_bytes)
    check_recording(loads_or_refuses(recording.load, folder / 'rec.csv'))
    shutil.rmtree(folder)


@SETTINGS
@given(text=st.one_of(st.text(max_size=300), st.binary(max_size=300)))
def test_any_manifest_text_is_read_or_refused(text):
    path = written('m.yaml', text.encode() if isinstance(text, str) else text)
    loads_or_refuses(recording.read_manifest, path)
    (path.parent / 'm.csv').write_bytes(CSV)
    check_recording(loads_or_refuses(recording.read_csv, path.parent / 'm.csv'))
    shutil.rmtree(path.parent)


yaml_values = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-10 ** 6, 10 ** 20),
              st.floats(allow_nan=True), st.text(max_size=8)),
    lambda inner: st.one_of(st.lists(inner, max_size=4),
                            st.dictionaries(st.text(max_size=6), inner, max_size=4)),
    max_leaves=12)


@SETTINGS
@given(changes=st.dictionaries(st.sampled_from(['format', 'source', 'sample_period_s',
                                                'conditions', 'samples', 'lost_steps',
                                                'channels', 'reading_range', 'noise']),
                               yaml_values, min_size=1, max_size=3))
def test_a_manifest_with_any_values_loads_or_is_refused(changes):
    manifest = {**yaml.safe_load(MANIFEST), **changes}
    path = written('r.yaml', yaml.safe_dump(manifest).encode())
    (path.parent / 'r.csv').write_bytes(CSV)
    check_recording(loads_or_refuses(recording.read_csv, path.parent / 'r.csv'))
    shutil.rmtree(path.parent)


def _mcap(folder: Path) -> Path:
    return next(folder.glob('*.mcap'))


@settings(SETTINGS, max_examples=max(EXAMPLES // 2, 10))
@given(data=st.data(), which=st.sampled_from(['mcap', 'metadata']))
def test_a_damaged_bag_loads_or_is_refused(data, which):
    folder = Path(tempfile.mkdtemp(dir=WORK)) / 'bag'
    shutil.copytree(BAG, folder)
    target = _mcap(folder) if which == 'mcap' else folder / 'metadata.yaml'
    target.write_bytes(damaged(data, target.read_bytes(), most=3))
    check_recording(loads_or_refuses(read_bag, folder))
    shutil.rmtree(folder.parent)


# -- settings -----------------------------------------------------------------------------

REPLICATE_KEYS = sorted(replicate_config.DEFAULTS)
SIM_KEYS = sorted(simconfig.KNOWN)


def settings_file(data) -> bytes:
    """A settings file as text: random YAML, or random values under real keys."""
    return data.draw(st.one_of(st.binary(max_size=200), st.text(max_size=200).map(str.encode)))


@SETTINGS
@given(data=st.data(), keys=st.dictionaries(st.sampled_from(REPLICATE_KEYS), yaml_values,
                                            max_size=3),
       nested=st.sampled_from(['phase1', 'phase2', 'task', 'reality', 'levels', 'backend']),
       inner=st.dictionaries(st.text(max_size=12), yaml_values, max_size=3))
def test_any_replicate_config_loads_or_is_refused(data, keys, nested, inner):
    for content in (settings_file(data), yaml.safe_dump(keys).encode(),
                    yaml.safe_dump({nested: inner}).encode(),
                    yaml.safe_dump({nested: {k: v for k, v in zip(
                        replicate_config.DEFAULTS[nested] if isinstance(
                            replicate_config.DEFAULTS[nested], dict) else {}, inner.values())
                    }}).encode()):
        path = written('c.yaml', content)
        config = loads_or_refuses(replicate_config.load, path)
        if config is not None:
            assert config.hash and config.conditions
        shutil.rmtree(path.parent)


@SETTINGS
@given(data=st.data(), effect=st.sampled_from(EFFECTS),
       fields=st.dictionaries(st.text(max_size=14), yaml_values, max_size=3),
       top=st.dictionaries(st.sampled_from(['format', 'base', 'sensor_noise', 'effects']),
                           yaml_values, max_size=2))
def test_any_effects_config_loads_or_is_refused(data, effect, fields, top):
    real = EffectsConfig.real_robot().to_dict()['effects'][effect]
    known = {k: v for k, v in zip(real, fields.values())}      # real field names, any values
    for content in (settings_file(data), yaml.safe_dump(top).encode(),
                    yaml.safe_dump({'effects': {effect: fields}}).encode(),
                    yaml.safe_dump({'effects': {effect: known}}).encode()):
        path = written('e.yaml', content)
        loads_or_refuses(EffectsConfig.load, path)
        shutil.rmtree(path.parent)


@SETTINGS
@given(data=st.data(), values=st.dictionaries(st.sampled_from(SIM_KEYS), yaml_values,
                                              max_size=4),
       node=st.sampled_from(['/**', 'simulator', '/w0/simulator']))
def test_any_simulator_params_file_loads_or_is_refused(data, values, node):
    for content in (settings_file(data), yaml.safe_dump({node: values}).encode(),
                    yaml.safe_dump({node: {'ros__parameters': values}}).encode()):
        path = written('p.yaml', content)
        loads_or_refuses(simconfig.load, path)
        shutil.rmtree(path.parent)


def test_the_damaging_strategies_start_from_files_that_load():
    """So a refusal above is the damage's doing, not the original's."""
    folder = written('ok.csv', CSV).parent
    (folder / 'ok.yaml').write_bytes(MANIFEST)
    check_recording(recording.load(folder / 'ok.csv'))
    check_recording(read_bag(BAG))
    assert isinstance(replicate_config.load(None), replicate_config.ReplicateConfig)


# -- the evolution checkpoint -----------------------------------------------------------

@SETTINGS
@given(data=st.data(), values=st.dictionaries(
    st.sampled_from(['format', 'config', 'generation', 'history', 'batches', 'episodes']),
    yaml_values, max_size=4))
def test_any_checkpoint_file_loads_or_is_refused(data, values):
    path = written('run.checkpoint.json', data.draw(st.one_of(
        st.binary(max_size=100),
        st.just(json.dumps({'format': CHECKPOINT, 'config': {}, 'batches': [], **values},
                           default=str).encode()))))
    checkpoint = Checkpoint(path, {})
    if loads_or_refuses(checkpoint.load):
        assert all(isinstance(b['fitness'], list) for b in checkpoint.batches)
    shutil.rmtree(path.parent)


# -- the simulator's effects parameter (effects/) ---------------------------------------

@SETTINGS
@given(data=st.data())
def test_any_effects_parameter_loads_or_is_refused(data):
    name = data.draw(st.sampled_from(sorted(fx.REGISTRY)))
    fields = [f.name for f in dataclasses.fields(fx.REGISTRY[name])]
    effect = {'name': name, **data.draw(st.dictionaries(
        st.sampled_from(fields + ['junk']), yaml_values, max_size=len(fields)))}
    text = data.draw(st.one_of(st.just(json.dumps([effect], default=str)),
                               st.text(max_size=60), st.just(json.dumps(effect, default=str))))
    loaded = loads_or_refuses(fx.loads, text)
    if loaded:
        assert fx.loads(fx.dumps(loaded)) == loaded       # what loads, writes back the same


ODD = [None, [], {}, 'x', -1, 1.5, 10 ** 30, float('nan'), [[1]], [None], {'a': None}]


def test_every_setting_of_every_loader_with_an_odd_value_loads_or_is_refused():
    """Each top-level key (and each field one level down) of the replicate config, the
    effects file and the simulator parameters, set in turn to each odd value."""
    cases = []
    for key, default in replicate_config.DEFAULTS.items():
        cases += [(replicate_config.load, {key: v}) for v in ODD]
        if isinstance(default, dict):
            cases += [(replicate_config.load, {key: {k: v}}) for k in default for v in ODD]
    for effect, fields in EffectsConfig.real_robot().to_dict()['effects'].items():
        cases += [(EffectsConfig.load, {'effects': {effect: {k: v}}}) for k in fields
                  for v in ODD]
    cases += [(EffectsConfig.load, {k: v}) for k in ('format', 'base', 'sensor_noise',
                                                     'effects') for v in ODD]
    cases += [(simconfig.load, {'/**': {'ros__parameters': {k: v}}}) for k in SIM_KEYS
              for v in ODD]
    for load, content in cases:
        path = written('odd.yaml', yaml.safe_dump(content).encode())
        loads_or_refuses(load, path)
        shutil.rmtree(path.parent)
    assert len(cases) > 500
