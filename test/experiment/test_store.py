"""The resumable results store: atomic units, checkpoints, and refusing other settings."""
import json

import numpy as np
import pytest

from khepera_noise_ros.core.evolution import EAConfig, SteadyStateEA
from khepera_noise_ros.experiment.protocol import replay
from khepera_noise_ros.experiment.store import SettingsMismatch, Store


def opened(tmp_path, config_hash='aaaa', fresh=False) -> Store:
    store = Store(tmp_path, config_hash)
    store.open(f'hash: {config_hash}\n', fresh=fresh)
    return store


def test_a_saved_unit_loads_back_with_its_identity(tmp_path):
    store = opened(tmp_path)
    assert store.load('5pct-combination', 0, 1) is None
    store.save('5pct-combination', 0, 1, {'best_fitness': 0.8})
    unit = store.load('5pct-combination', 0, 1)
    assert unit['best_fitness'] == 0.8
    assert (unit['condition'], unit['trial'], unit['step'], unit['config_hash']) == \
        ('5pct-combination', 0, 1, 'aaaa')


def test_half_written_and_foreign_files_are_not_results(tmp_path):
    store = opened(tmp_path)
    path = store.path('5pct-combination', 0, 2)
    path.parent.mkdir(parents=True)
    path.with_name('.step2.json.123.tmp').write_text('{"format": ')       # a killed write
    assert store.load('5pct-combination', 0, 2) is None
    path.write_text('{"format": "khepera-noise-replicate-unit/1", "mean"')  # damaged by hand
    assert store.load('5pct-combination', 0, 2) is None
    path.write_text(json.dumps({'mean': 0.5}))                               # not ours
    assert store.load('5pct-combination', 0, 2) is None
    store.save('5pct-combination', 0, 2, {'mean': 0.5})
    assert store.load('5pct-combination', 0, 2)['mean'] == 0.5


def test_a_checkpoint_lives_until_its_unit_is_saved(tmp_path):
    store = opened(tmp_path)
    store.save_checkpoint('c', 1, 4, [0.1, 0.25])
    assert store.load_checkpoint('c', 1, 4) == [0.1, 0.25]
    assert store.load('c', 1, 4) is None
    store.save('c', 1, 4, {'best_fitness': 0.25})
    assert store.load_checkpoint('c', 1, 4) == []


def test_other_settings_are_refused_unless_fresh(tmp_path):
    store = opened(tmp_path, 'aaaa')
    store.save('c', 0, 1, {'best_fitness': 0.8})
    with pytest.raises(SettingsMismatch, match='hash aaaa there, bbbb now.*--fresh'):
        opened(tmp_path, 'bbbb')
    store = opened(tmp_path, 'bbbb', fresh=True)
    assert store.load('c', 0, 1) is None
    assert opened(tmp_path, 'bbbb').hash == 'bbbb'      # an empty directory takes any settings


def test_a_unit_from_other_settings_is_refused(tmp_path):
    opened(tmp_path, 'aaaa').save('c', 0, 1, {'best_fitness': 0.8})
    with pytest.raises(SettingsMismatch, match='other settings'):
        Store(tmp_path, 'bbbb').load('c', 0, 1)


def test_sessions_add_up(tmp_path):
    store = opened(tmp_path)
    store.record_session(12.5, False, {'simulation': 'core'})
    sessions = store.record_session(3.0, True, {'simulation': 'core'})
    assert [s['elapsed_s'] for s in sessions] == [12.5, 3.0]
    assert [s['finished'] for s in Store(tmp_path, 'aaaa').sessions()] == [False, True]


def test_replaying_told_fitness_restores_an_ea_exactly():
    config = EAConfig(population=5, generations=4)

    def fitness(genomes):
        return np.tanh(genomes.sum(axis=1))

    whole = SteadyStateEA(config, seed=9)
    told = []
    while not whole.done:
        f = fitness(whole.ask()[0])
        told.extend(f.tolist())
        whole.tell(f)
    resumed = SteadyStateEA(config, seed=9)
    replay(resumed, told[:13])                     # stopped after 13 evaluations
    while not resumed.done:
        resumed.tell(fitness(resumed.ask()[0]))
    assert np.array_equal(resumed.best_genome, whole.best_genome)
    assert resumed.best_generation == whole.best_generation
    assert [h.best for h in resumed.history] == [h.best for h in whole.history]
    with pytest.raises(ValueError, match='does not fit'):
        replay(SteadyStateEA(config, seed=9), told + [0.5])
