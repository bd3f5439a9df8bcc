"""The robot, the light-centring task, the 6-2-2 network and the EA."""
import re

import numpy as np
import pytest

from khepera_noise_ros.core import baseline, evolution, khepera, network, task
from khepera_noise_ros.core.evaluation import CoreEvaluator
from khepera_noise_ros.core.noise import NoiseModel


def test_light_response_follows_michels_formula():
    w = khepera.World(lamp_distance_mm=50.0, gain=450.0)
    assert w.response(0.0) == pytest.approx(500 - 200 / 250 * 450)
    assert w.response(30.0) == pytest.approx(500 - np.cos(np.radians(45)) * 200 / 250 * 450)
    assert w.response(61.0) == 500.0 and w.response(180.0) == 500.0
    assert khepera.World(lamp_distance_mm=0).response(0.0) == 50.0  # floored


def test_light_table_faces_each_sensor_to_its_own_angle():
    table = khepera.World(lamp_distance_mm=100).light_table()
    for s, angle in enumerate(khepera.SENSOR_ANGLES_DEG):
        brightest = np.flatnonzero(table[s] == table[s].min())   # a small plateau after rounding
        assert khepera.to_tenths(angle) in brightest


def test_turning_right_moves_the_lamp_to_the_left():
    w = khepera.World(deg_per_power=3.0)
    b = khepera.to_tenths([0.0, 0.0, 10.0])
    after = khepera.turn(b, np.array([1, -1, -1]), np.array([2, 2, 0]), w)
    assert np.allclose(khepera.to_degrees(after), [6.0, -6.0, 10.0])


def test_fitness_factors_are_the_papers():
    r = np.array([[100.0, 100.0, 100.0, 400.0, 400.0, 400.0, 0, 0]])
    balance, intensity, turning = task.fitness_factors(r, np.array([3]))
    assert balance[0] == pytest.approx(1 - 300 / 525)
    assert intensity[0] == pytest.approx(1 - 250 / 525)
    assert turning[0] == 1.0
    assert task.step_fitness(r, np.array([0]))[0] == 0.0


def test_episode_fitness_is_in_unit_interval_for_random_genomes():
    g = np.random.default_rng(0).uniform(-5, 5, (500, network.GENES))
    f = CoreEvaluator(noise=NoiseModel('combination', 0.3, 0.3))(g, np.arange(500))
    assert ((f >= 0) & (f <= 1)).all() and f.std() > 0


def test_perturbation_every_five_steps():
    env = task.Episodes(noise=NoiseModel('none'), task=task.Task(steps=12, perturbation_deg=40))
    env.reset([7, 8])
    bearings = [env.bearing_deg.copy()]
    while not env.done:
        env.step(np.ones(2, int), np.zeros(2, int))   # power 0: only perturbations move it
        if not env.done:
            bearings.append(env.bearing_deg.copy())
    moved = [i for i in range(1, 12) if not np.allclose(bearings[i], bearings[i - 1])]
    assert moved == [5, 10]
    assert np.abs(np.array(bearings)).max() <= 80


def test_readings_follow_the_bearing_over_long_fast_turning_episodes():
    """Bearings are wrapped only every few steps: the look-up must wrap them itself."""
    world = khepera.World(deg_per_power=40.0)
    env = task.Episodes(world, NoiseModel('none'), task.Task(steps=400, perturbation_deg=180))
    readings, table = env.reset(np.arange(64)), world.light_table()
    rng = np.random.default_rng(3)
    while readings is not None:
        index = khepera.to_tenths(env.bearing_deg)
        assert np.array_equal(readings, table[:, index].T)
        assert (np.abs(env.bearing_deg) <= 180).all()
        readings = env.step(rng.choice([-1, 1], 64), rng.integers(7, 10, 64))


def test_handwritten_controller_scores_like_figure_8():
    f = task.run(baseline.turn_toward_light, np.arange(400))
    assert 0.75 < f.mean() < 0.85       # the paper's evolved controller: 0.818
    trace = task.run(baseline.turn_toward_light, np.arange(3), trace=True)
    assert trace.fitness.shape == (60, 3)
    assert np.allclose(trace.fitness.mean(axis=0), task.run(baseline.turn_toward_light,
                                                            np.arange(3)))


def test_same_seed_same_episode_and_batch_independence():
    g = np.random.default_rng(1).uniform(-1, 1, (4, network.GENES))
    ev = CoreEvaluator()
    assert np.array_equal(ev(g, [1, 2, 3, 4]), ev(g, [1, 2, 3, 4]))
    assert ev(g[2:3], [3])[0] == ev(g, [1, 2, 3, 4])[2]
    assert not np.array_equal(ev(g, [1, 2, 3, 4]), ev(g, [5, 6, 7, 8]))


def test_genome_layout_round_trips():
    g = np.random.default_rng(2).normal(size=(5, network.GENES))
    w = network.unpack(g)
    assert w.w_ih.shape == (6, 2, 5) and w.w_ho.shape == (2, 2, 5)
    assert np.allclose(network.pack(w), g.astype(np.float32))
    assert w.w_ih[3, 1, 0] == np.float32(g[0, 2 * 3 + 1])
    assert w.b_o[1, 4] == np.float32(g[4, 19])


def test_network_outputs_map_to_direction_and_power():
    g = np.zeros((2, network.GENES))
    g[0, 18], g[0, 19] = -5.0, 5.0     # output 0 low -> left, output 1 high -> power 9
    g[1, 18], g[1, 19] = 5.0, -0.2     # output 0 high -> right, sigmoid(-0.2)=0.45 -> power 4
    direction, power = network.act(network.unpack(g), np.full((2, 8), 300.0, np.float32))
    assert direction.tolist() == [-1, 1] and power.tolist() == [9, 4]


def test_sensor_major_readings_are_refused_not_broadcast():
    """One robot's readings as an (8, 1) column would broadcast into eight one-sensor
    robots; the network refuses them instead of answering for the wrong robot."""
    weights = network.unpack(np.zeros((1, network.GENES)))
    with pytest.raises(ValueError, match='batch first'):
        network.act(weights, np.full((8, 1), 300.0, np.float32))
    direction, power = network.act(weights, np.full((1, 8), 300.0, np.float32))
    assert direction.shape == power.shape == (1,)


@pytest.mark.parametrize('bad', [np.zeros(19), np.zeros((2, 21)), [np.nan] * 20])
def test_bad_genomes_are_named(bad):
    with pytest.raises(ValueError, match='gene'):
        network.check_genomes(bad)


@pytest.mark.parametrize('value', [np.nan, np.inf, -np.inf, 1.0001e30, -2e30])
def test_the_bad_gene_is_the_one_named(value):
    genomes = np.zeros((3, network.GENES))
    genomes[2, 7] = value
    with pytest.raises(ValueError, match=re.escape(f'genome 2 gene 7 is {value};')):
        network.check_genomes(genomes)
    genomes[2, 7] = -1e30                               # the limit itself is a gene
    assert network.check_genomes(genomes)[2, 7] == -1e30


def test_ea_is_reproducible_and_improves():
    ev = CoreEvaluator(task=task.Task(steps=30))
    cfg = evolution.EAConfig(population=10, generations=8)
    runs = []
    for _ in range(2):
        ea = evolution.SteadyStateEA(cfg, seed=4)
        evolution.evolve([ea], ev)
        runs.append(ea)
    a, b = runs
    assert np.array_equal(a.best_genome, b.best_genome) and a.best_fitness == b.best_fitness
    assert a.evaluations == 10 + 8 * 10
    assert a.history[-1].best >= a.history[0].best
    assert ev(np.repeat(a.best_genome[None], 50, 0), np.arange(50)).mean() > \
        ev(np.repeat(a.population[:1] * 0, 50, 0), np.arange(50)).mean()


def test_batched_trials_equal_separate_trials():
    ev = CoreEvaluator(task=task.Task(steps=20))
    cfg = evolution.EAConfig(population=6, generations=3, fitness='reevaluate', best='retest')
    together = [evolution.SteadyStateEA(cfg, seed=s) for s in (1, 2)]
    evolution.evolve(together, ev)
    alone = evolution.SteadyStateEA(cfg, seed=2)
    evolution.evolve([alone], ev)
    assert np.array_equal(together[1].best_genome, alone.best_genome)
    assert alone.evaluations == 6 + 3 * 6 * 2 + 6 * cfg.retest_episodes


def test_seeded_start_is_seed_plus_uniform_mutation():
    seed = np.linspace(-1, 1, network.GENES)
    ea = evolution.SteadyStateEA(evolution.PHASE2, seed=0, seed_genome=seed)
    genomes, seeds = ea.ask()
    assert genomes.shape == (10, 20) and seeds.shape == (10,)
    assert (np.abs(genomes - seed) <= 1.0).all() and not np.allclose(genomes, seed)
    random = evolution.SteadyStateEA(evolution.PHASE1, seed=0).ask()[0]
    assert (np.abs(random) <= 0.4).all()


def test_ea_rejects_bad_settings_and_fitness():
    with pytest.raises(ValueError, match="'median'"):
        evolution.EAConfig(best='median')
    ea = evolution.SteadyStateEA(evolution.EAConfig(population=2, generations=1))
    with pytest.raises(ValueError, match='2 finite fitness'):
        ea.tell([0.5])


def _sequential_reference(cfg, seed, evaluate):
    """The appendix's EA written the plain way: one tournament after another."""
    rng = np.random.default_rng(seed)
    pop = rng.uniform(-cfg.init_range, cfg.init_range, (cfg.population, network.GENES))
    fit = evaluate(pop, rng.integers(0, 2**53, cfg.population)).astype(float)
    per = 2 if cfg.fitness == 'reevaluate' else 1
    draws = [(rng.choice(cfg.population, 2, replace=False),
              rng.uniform(-cfg.mutation_range, cfg.mutation_range, network.GENES),
              rng.integers(0, 2**53, per)) for _ in range(cfg.generations * cfg.population)]
    best, history = (fit.max(), 0), [fit.max()]
    for k, ((i, j), noise, seeds) in enumerate(draws):
        if cfg.fitness == 'reevaluate':
            fit[[i, j]] = evaluate(pop[[i, j]], seeds)
            best = max(best, (fit[i], k // cfg.population + 1), (fit[j], k // cfg.population + 1),
                       key=lambda b: b[0])
        w, loser = (i, j) if fit[i] >= fit[j] else (j, i)
        pop[loser] = pop[w] + noise
        fit[loser] = -np.inf
        if cfg.fitness == 'stored':
            fit[loser] = evaluate(pop[loser][None], seeds)[0]
            best = max(best, (fit[loser], k // cfg.population + 1), key=lambda b: b[0])
        if (k + 1) % cfg.population == 0:
            history.append(fit[np.isfinite(fit)].max())
    return pop, best, history


@pytest.mark.parametrize('mode', evolution.FITNESS_MODES)
def test_batched_tournaments_equal_the_sequential_algorithm(mode):
    ev = CoreEvaluator(task=task.Task(steps=15))
    cfg = evolution.EAConfig(population=12, generations=6, fitness=mode)
    ea = evolution.SteadyStateEA(cfg, seed=11)
    rounds = 0
    while not ea.done:
        ea.tell(ev(*ea.ask()))
        rounds += 1
    pop, (best, generation), history = _sequential_reference(cfg, 11, ev)
    assert np.array_equal(ea.population, pop)
    assert ea.best_fitness == best and ea.best_generation == generation
    assert [h.best for h in ea.history] == history
    sequential_rounds = 1 + cfg.generations * cfg.population
    assert rounds < sequential_rounds / 2      # disjoint tournaments share a batch
