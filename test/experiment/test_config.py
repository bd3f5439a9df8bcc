"""Settings of the replication: the paper's defaults, files, overrides and errors."""
from pathlib import Path

import pytest

from khepera_noise_ros.core.noise import DEFAULT_GROUPS
from khepera_noise_ros.experiment import config

SHIPPED = Path(__file__).resolve().parents[2] / 'config' / 'replicate.yaml'


def test_defaults_are_the_papers_experiment():
    c = config.load()
    assert [lv.label for lv in c.levels] == ['5%', '10%']
    names = [cond.name for cond in c.conditions]
    assert names == ['5% combination', '5% independent', '10% combination', '10% independent']
    levels = {cond.name: (cond.noise.model, *cond.noise.levels) for cond in c.conditions}
    assert levels == {'5% combination': ('combination', 0.03, 0.02),
                      '5% independent': ('independent', 0.0, 0.05),
                      '10% combination': ('combination', 0.05, 0.05),
                      '10% independent': ('independent', 0.0, 0.10)}
    assert all(cond.noise.groups == DEFAULT_GROUPS for cond in c.conditions)
    assert c.trials == 10
    assert (c.phase1.population, c.phase1.generations, c.phase1.init_range) == (25, 50, 0.4)
    assert (c.phase2.population, c.phase2.generations, c.phase2.mutation_range) == (10, 5, 1.0)
    assert (c.task.steps, c.task.perturb_every) == (60, 5)
    assert c.backend == {'simulation': 'graph', 'reality': 'emulator'}
    assert c.ceiling is None                      # the ceiling arm runs when asked for


def test_the_ceiling_arm_is_phase_2_with_the_full_budget_and_keeps_the_hash():
    plain, arm = config.load(), config.load(overrides={'ceiling': {'enabled': True}})
    assert (arm.ceiling.population, arm.ceiling.generations) == \
        (plain.phase1.population, plain.phase1.generations)
    assert arm.ceiling.mutation_range == plain.phase2.mutation_range
    assert arm.ceiling.best == plain.phase2.best
    assert arm.hash == plain.hash                 # resuming with the arm keeps steps 1-5
    longer = config.load(overrides={'ceiling': {'enabled': True, 'generations': 80}})
    assert longer.hash != plain.hash and longer.ceiling.generations == 80


def test_the_shipped_file_holds_the_defaults():
    assert config.load(SHIPPED).data == config.load().data


def test_quick_has_fewer_trials_and_the_same_protocol():
    full, quick = config.load(), config.load(quick=True)
    assert quick.trials < full.trials
    assert {k: v for k, v in quick.data.items() if k != 'trials'} == \
        {k: v for k, v in full.data.items() if k != 'trials'}
    assert quick.hash != full.hash


def test_a_file_overrides_only_what_it_names(tmp_path):
    path = tmp_path / 'c.yaml'
    path.write_text('dependence_groups: [[0, 1, 2], [3, 4, 5]]\nphase1: {generations: 7}\n'
                    'levels:\n  - {label: 8%, figure: fig9, combination: {dependent: 0.06, '
                    'independent: 0.02}, independent: 0.08}\n')
    c = config.load(path)
    assert c.phase1.generations == 7 and c.phase1.population == 25
    assert [cond.name for cond in c.conditions] == ['8% combination', '8% independent']
    assert c.conditions[0].noise.groups == ((0, 1, 2), (3, 4, 5))
    assert c.conditions[0].key == '8pct-combination'


def test_the_written_settings_read_back_to_the_same_hash(tmp_path):
    c = config.load(overrides={'trials': 4, 'reality': {'effects': {'base': 'none'}}})
    (tmp_path / 'config.yaml').write_text(c.to_yaml())
    again = config.load(tmp_path / 'config.yaml')
    assert again.hash == c.hash and again.trials == 4
    assert again.effects.enabled == ()


def test_the_hash_follows_every_setting():
    base = config.load()
    assert config.load(overrides={'seed': 2}).hash != base.hash
    assert config.load(overrides={'reality': {'robots': 8}}).hash != base.hash
    assert config.load(overrides={'backend': {'simulation': 'core'}}).hash != base.hash
    assert config.load(overrides={'seed': base.seed}).hash == base.hash


@pytest.mark.parametrize('text, match', [
    ('trails: 3\n', "unknown setting 'trails'"),
    ('phase1: {generation: 3}\n', "unknown setting 'phase1.generation'"),
    ('trials: 1\n', 'trials must be an integer >= 2, got 1'),
    ('phase2: {population: 1}\n', 'phase2: population must be an integer >= 2'),
    ('dependence_groups: [[0, 1], [1, 2]]\n', 'must not overlap'),
    ('levels: [{label: 5%, figure: f, combination: {dependent: 2.0, independent: 0.1}, '
     'independent: 0.05}]\n', r'levels\[0\] \(5%\): dependent noise level'),
    ('levels: [{label: 5%, independent: 0.05}]\n', 'must have exactly the keys'),
    ('backend: {simulation: gazebo}\n', "backend.simulation must be one of"),
    ('reality: {effects: {effects: {flicker: {}}}}\n', 'unknown effect'),
    ('ceiling: {enabled: 1}\n', 'ceiling.enabled must be true or false, got 1'),
    ('ceiling: {generations: 0}\n', 'ceiling.generations must be an integer >= 1, got 0'),
    ('ceiling: {budget: 3}\n', "unknown setting 'ceiling.budget'"),
    ('- 1\n', 'must hold a mapping'),
])
def test_bad_settings_are_refused_with_their_name(tmp_path, text, match):
    path = tmp_path / 'bad.yaml'
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        config.load(path)


def test_an_effects_file_is_found_beside_the_config_and_written_in_full(tmp_path):
    (tmp_path / 'room.yaml').write_text('base: none\neffects: {temporal_drift: {enabled: true}}\n')
    (tmp_path / 'c.yaml').write_text('reality: {effects: room.yaml}\n')
    c = config.load(tmp_path / 'c.yaml')
    assert c.effects.enabled == ('temporal_drift',)
    assert c.reality['effects']['effects']['temporal_drift']['enabled'] is True
    (tmp_path / 'missing.yaml').write_text('reality: {effects: nowhere.yaml}\n')
    with pytest.raises(FileNotFoundError):
        config.load(tmp_path / 'missing.yaml')
