"""Steps 1-5 at a tiny scale, in process: structure, seeding, batching and resuming."""
import numpy as np
import pytest

from khepera_noise_ros.core.evaluation import CoreEvaluator
from khepera_noise_ros.core.evolution import SteadyStateEA
from khepera_noise_ros.experiment.protocol import STEPS, Backends, ConditionEpisodes, \
    Experiment, core_simulate, episodes_per_run, per_condition, seed_for
from khepera_noise_ros.experiment.store import Store
from khepera_noise_ros.experiment import config as settings
from khepera_noise_ros.testing.experiments import TINY, backends, run, tiny


def scores(store, config) -> dict:
    return {(c.key, t, s): store.load(c.key, t, s) for c in config.conditions
            for t in range(config.trials) for s in STEPS}


def test_every_trial_goes_through_the_five_steps_in_order(tmp_path):
    config = tiny()
    store, experiment = run(config, tmp_path)
    units = scores(store, config)
    assert all(u is not None for u in units.values())
    for c in config.conditions:
        for t in range(config.trials):
            u = {s: units[c.key, t, s] for s in STEPS}
            assert [u[s]['world'] for s in STEPS] == ['simulation'] * 2 + ['reality'] * 3
            best1, best4 = u[1]['best_genome'], u[4]['best_genome']
            assert u[2]['genome'] == best1 and u[3]['genome'] == best1
            assert u[4]['seed_genome'] == best1                 # phase 2 starts from phase 1
            assert u[5]['genome'] == best4
            assert u[2]['seeds'] == u[3]['seeds'] == u[5]['seeds']  # the same test episodes
            assert len(u[3]['fitness']) == config.test_episodes
            retests = 4 * config.phase1.retest_episodes if config.phase1.best == 'retest' else 0
            assert u[1]['evaluations'] == episodes_per_run(config.phase1) == 4 + 3 * 4 + retests
            assert len(u[1]['history']) == config.phase1.generations + 1
            assert 0 <= u[1]['best_generation'] <= config.phase1.generations
            assert all(0.0 <= f <= 1.0 for s in (2, 3, 5) for f in u[s]['fitness'])
    # the reality evaluator ran exactly steps 3, 4 and 5, all conditions in each batch
    spy = experiment.backends.reality
    units_n = len(config.conditions) * config.trials
    assert spy.episodes == units_n * (2 * config.test_episodes + episodes_per_run(config.phase2))
    step3_genomes = spy.batches[0][0]
    assert [g.tolist() for g in step3_genomes[::config.test_episodes]] == \
        [units[c.key, t, 1]['best_genome'] for c in config.conditions
         for t in range(config.trials)]
    assert experiment.episodes_left() == {'simulation': 0, 'reality': 0}


def test_real_tests_record_each_step_and_score_as_untraced(tmp_path):
    config = tiny()
    plain, _ = run(config, tmp_path, 'plain')
    store, experiment = run(config, tmp_path, 'traced',
                            backends=backends(config, reality_spy=False, traced=True))
    assert scores(store, config).keys() == scores(plain, config).keys()
    for key, unit in scores(store, config).items():
        assert unit['fitness' if key[2] in (2, 3, 5) else 'best_fitness'] == \
            scores(plain, config)[key]['fitness' if key[2] in (2, 3, 5) else 'best_fitness']
        if key[2] in (3, 5):
            steps = np.array(unit['step_fitness'])
            assert steps.shape == (config.test_episodes, config.task.steps)
            assert unit['fitness'] == pytest.approx(steps.mean(axis=1).tolist(), abs=1e-6)


def test_a_trial_does_not_depend_on_what_else_is_in_its_batch(tmp_path):
    two, three = tiny(), tiny(trials=3)
    a, _ = run(two, tmp_path, 'two')
    b, _ = run(three, tmp_path, 'three')
    for c in two.conditions:
        for t in range(2):
            for s in (1, 2):        # simulation: per-episode seeds, whatever the batch
                assert a.load(c.key, t, s)['history' if s == 1 else 'fitness'] == \
                    b.load(c.key, t, s)['history' if s == 1 else 'fitness']


def test_one_batch_for_all_conditions_equals_one_evaluator_each():
    config = tiny()
    noise = {c.key: c.noise for c in config.conditions}
    rng = np.random.default_rng(1)
    requests = {k: (rng.uniform(-2, 2, (n, 20)), rng.integers(0, 2**40, n))
                for k, n in zip(noise, (3, 1, 4, 2))}
    together = core_simulate(noise, config.world, config.task)(requests)
    apart = per_condition({k: CoreEvaluator(config.world, m, config.task)
                           for k, m in noise.items()})(requests)
    assert together.keys() == apart.keys()
    for k in noise:
        assert np.array_equal(together[k], apart[k])
    episodes = ConditionEpisodes(noise, config.world, config.task)
    with pytest.raises(KeyError):
        episodes.lay_out({'no-such-condition': 2})


class Interrupt:
    """Evaluates normally, then raises KeyboardInterrupt at the n-th call (Ctrl-C)."""

    def __init__(self, simulate, at: int):
        self.simulate, self.at, self.calls = simulate, at, 0

    def __call__(self, requests):
        self.calls += 1
        if self.calls == self.at:
            raise KeyboardInterrupt
        return self.simulate(requests)


def rounds_in(ea: SteadyStateEA, told: list[float]) -> int:
    """How many ask/tell rounds the logged values fill on a fresh EA, exactly."""
    rounds = used = 0
    while used < len(told):
        size = len(ea.ask()[1])
        assert 0 < size <= len(told) - used, 'the log ends inside a round'
        ea.tell(told[used:used + size])
        used, rounds = used + size, rounds + 1
    return rounds


def test_an_interrupted_run_resumes_without_recomputing(tmp_path):
    config = tiny()
    noise = {c.key: c.noise for c in config.conditions}
    simulate = core_simulate(noise, config.world, config.task)
    whole_count = Interrupt(simulate, at=0)
    whole, _ = run(config, tmp_path, 'whole', backends=backends(config, simulate=whole_count))
    phase1_rounds = whole_count.calls - 1             # then one call for step 2
    cut = phase1_rounds // 2
    assert cut >= 2
    stopping = Interrupt(simulate, at=cut + 1)        # mid phase 1
    with pytest.raises(KeyboardInterrupt):
        run(config, tmp_path, 'cut', backends=backends(config, simulate=stopping),
            checkpoint_s=1e9)                     # checkpoints written on the way out
    store = Store(tmp_path / 'cut', config.hash)
    units = [(c, t) for c in config.conditions for t in range(config.trials)]
    assert all(store.load(c.key, t, 1) is None for c, t in units)
    told = {(c.key, t): store.load_checkpoint(c.key, t, 1) for c, t in units}
    for (key, t), values in told.items():       # exactly the rounds that were answered
        ea = SteadyStateEA(config.phase1, seed=seed_for(config.seed, key, t, 'phase1'))
        assert rounds_in(ea, values) == cut
    left = Experiment(config, backends(config), store).episodes_left()
    per_run = episodes_per_run(config.phase1)
    assert left == {'simulation': sum(per_run - len(v) + config.test_episodes
                                      for v in told.values()),
                    'reality': len(units) * (2 + episodes_per_run(config.phase2) + 2)}
    counting = Interrupt(simulate, at=0)
    resumed, experiment = run(config, tmp_path, 'cut', backends=backends(config,
                                                                         simulate=counting))
    assert counting.calls == phase1_rounds - cut + 1   # the rounds left of phase 1, step 2
    assert scores(resumed, config) == scores(whole, config)
    assert experiment.episodes_left() == {'simulation': 0, 'reality': 0}


def test_an_interruption_in_reality_resumes_mid_phase_2(tmp_path):
    config = tiny()
    real = backends(config, reality_spy=False)
    calls = {'n': 0}

    def stopping(genomes, seeds):
        calls['n'] += 1
        if calls['n'] == 4:                       # step 3, then rounds 0-1 of phase 2
            raise KeyboardInterrupt
        return real.reality(genomes, seeds)

    with pytest.raises(KeyboardInterrupt):
        run(config, tmp_path, backends=Backends(real.simulate, stopping, real.reality_trace),
            checkpoint_s=1e9)
    store = Store(tmp_path / 'out', config.hash)
    told = store.load_checkpoint(config.conditions[0].key, 0, 4)
    best = store.load(config.conditions[0].key, 0, 1)['best_genome']
    ea = SteadyStateEA(config.phase2, seed=seed_for(config.seed, config.conditions[0].key, 0,
                                                    'phase2'), seed_genome=best)
    assert rounds_in(ea, told) == 2               # the seeded population, one round
    left = sum(episodes_per_run(config.phase2) - len(store.load_checkpoint(c.key, t, 4))
               + config.test_episodes for c in config.conditions for t in range(config.trials))
    again = backends(config)
    _, experiment = run(config, tmp_path, backends=again)
    assert again.reality.episodes == left
    assert store.load(config.conditions[0].key, 0, 5) is not None


def test_phase_2_re_tests_its_best_on_episodes_apart_from_the_final_test(tmp_path):
    config = tiny()
    assert config.phase2.best == 'retest'
    store, experiment = run(config, tmp_path)
    spy = experiment.backends.reality
    tests = {s for c in config.conditions for t in range(config.trials)
             for s in store.load(c.key, t, 5)['seeds']}
    step4 = spy.batches[1:-1]       # step 3 first, step 5 last, phase 2 in between
    evolution = {int(s) for _, seeds in step4 for s in seeds}
    assert evolution and not evolution & tests


def test_the_ceiling_arm_trains_the_same_bests_longer_and_tests_them_alike(tmp_path):
    config = settings.load(overrides={**TINY, 'ceiling': {'enabled': True, 'population': 4,
                                                          'generations': 3}})
    store, experiment = run(config, tmp_path)
    assert list(experiment.steps) == [1, 2, 3, 4, 5, 6, 7]
    for c in config.conditions:
        for t in range(config.trials):
            u = {s: store.load(c.key, t, s) for s in range(1, 8)}
            assert u[6]['world'] == u[7]['world'] == 'reality'
            assert u[6]['seed_genome'] == u[1]['best_genome']      # from phase 1's best
            assert u[7]['genome'] == u[6]['best_genome']
            assert u[7]['seeds'] == u[5]['seeds'] == u[3]['seeds']  # the same test episodes
            assert u[6]['evaluations'] == episodes_per_run(config.ceiling) > \
                u[4]['evaluations'] == episodes_per_run(config.phase2)
    assert experiment.episodes_left() == {'simulation': 0, 'reality': 0}


def test_a_run_resumed_with_the_ceiling_arm_keeps_its_steps_1_to_5(tmp_path):
    budget = {'population': 4, 'generations': 2}
    plain = settings.load(overrides={**TINY, 'ceiling': {'enabled': False, **budget}})
    store, _ = run(plain, tmp_path)
    files = sorted((tmp_path / 'out').rglob('step*.json'))
    stamps = {f: f.stat().st_mtime_ns for f in files}
    arm = settings.load(overrides={**TINY, 'ceiling': {'enabled': True, **budget}})
    assert arm.hash == plain.hash
    store, experiment = run(arm, tmp_path)
    assert all(f.stat().st_mtime_ns == stamps[f] for f in files)
    assert all(store.load(c.key, t, s) is not None for c in arm.conditions
               for t in range(arm.trials) for s in (6, 7))
