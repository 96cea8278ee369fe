"""Tests of the binary-coded genetic algorithm (vgtarm.ga).

Statistical checks use fixed seeds and bounds of about 5 binomial standard deviations, so they
are deterministic and would fail only for a real change of the sampled distribution.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from vgtarm import ga
from vgtarm.errors import InputError

SIGMAS = 5.0


def binomial_bound(n: int, p: float) -> float:
    """Half-width of a SIGMAS-sigma band for the fraction of successes in n Bernoulli(p)."""
    return SIGMAS * math.sqrt(p * (1.0 - p) / n)


def sphere(target: np.ndarray):
    """Vectorised squared distance to ``target``: (m, n) -> (m,)."""

    def cost(x: np.ndarray) -> np.ndarray:
        return np.sum((x - target) ** 2, axis=1)

    return cost


class Recorder:
    """Wrap a cost; keep every call's candidates and costs."""

    def __init__(self, cost):
        self.cost = cost
        self.calls: list[tuple[np.ndarray, np.ndarray]] = []

    def __call__(self, x: np.ndarray) -> np.ndarray:
        values = np.asarray(self.cost(x), dtype=float)
        self.calls.append((x.copy(), values.copy()))
        return values


# ---------------------------------------------------------------------------------------------
# Coding
# ---------------------------------------------------------------------------------------------

AWKWARD_BOUNDS = [
    (np.array([0.0, 0.1, -3.7, 2.0]), np.array([5000.0, 0.3, 1e-3, 2.0])),
    (np.array([-1.0, 1e-9, 0.7]), np.array([1.0, 3e-9, 0.7000001])),
]


@pytest.mark.parametrize("n_bits", [1, 3, 8, 16])
@pytest.mark.parametrize(("lower", "upper"), AWKWARD_BOUNDS)
def test_decode_hits_both_bounds_exactly(n_bits, lower, upper):
    n = lower.size * n_bits
    zeros = ga.decode(np.zeros(n, dtype=np.uint8), lower, upper, n_bits)
    ones = ga.decode(np.ones(n, dtype=np.uint8), lower, upper, n_bits)
    assert np.array_equal(zeros, lower)
    assert np.array_equal(ones, upper)


@pytest.mark.parametrize("n_bits", [1, 4, 8])
def test_decode_is_linear_and_monotone_in_the_code(n_bits):
    lower, upper = np.array([-2.5]), np.array([7.25])
    codes = np.arange(2**n_bits)
    bits = (codes[:, None] >> np.arange(n_bits - 1, -1, -1)) & 1  # MSB first
    values = ga.decode(bits, lower, upper, n_bits)[:, 0]
    expected = lower[0] + codes / (2**n_bits - 1) * (upper[0] - lower[0])
    np.testing.assert_allclose(values, expected, rtol=0, atol=1e-12)
    assert np.all(np.diff(values) > 0)


def test_decode_reads_msb_first_and_keeps_batch_shape():
    lower, upper = np.zeros(2), np.full(2, 255.0)
    bits = np.array([[1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1]])
    np.testing.assert_allclose(ga.decode(bits, lower, upper), [[128.0, 1.0]])
    batch = np.random.default_rng(0).integers(0, 2, size=(3, 4, 16))
    assert ga.decode(batch, lower, upper).shape == (3, 4, 2)


@pytest.mark.parametrize("n_bits", [2, 8, 12])
def test_encode_decode_round_trip_on_grid(n_bits):
    lower, upper = AWKWARD_BOUNDS[0]
    rng = np.random.default_rng(n_bits)
    bits = rng.integers(0, 2, size=(200, lower.size * n_bits)).astype(np.uint8)
    bits[:, (lower.size - 1) * n_bits :] = 0  # the last gene has lower == upper: code 0
    values = ga.decode(bits, lower, upper, n_bits)
    again = ga.encode(values, lower, upper, n_bits)
    assert again.dtype == np.uint8
    assert np.array_equal(again, bits)
    assert np.array_equal(ga.decode(again, lower, upper, n_bits), values)


def test_encode_takes_nearest_code_and_clips():
    lower, upper = np.array([0.0]), np.array([255.0])
    values = np.array([[-10.0], [0.4], [0.6], [100.2], [254.7], [1e9]])
    decoded = ga.decode(ga.encode(values, lower, upper), lower, upper)[:, 0]
    np.testing.assert_array_equal(decoded, [0.0, 0.0, 1.0, 100.0, 255.0, 255.0])


# ---------------------------------------------------------------------------------------------
# Selection
# ---------------------------------------------------------------------------------------------


def test_sus_gives_floor_or_ceil_of_the_expectation():
    rng = np.random.default_rng(123)
    for trial in range(300):
        size = int(rng.integers(1, 60))
        n = int(rng.integers(0, 80))
        raw = rng.exponential(size=size) * (rng.random(size) > 0.2)
        raw[rng.integers(size)] += 0.1  # positive sum
        chosen = ga.stochastic_universal_sampling(raw, n, trial)
        assert chosen.shape == (n,)
        assert np.all(np.diff(chosen) >= 0)
        copies = np.bincount(chosen, minlength=size)
        expected = raw * n / raw.sum()
        assert np.all(copies >= np.floor(expected - 1e-9))
        assert np.all(copies <= np.ceil(expected + 1e-9))


def test_sus_is_unbiased():
    expectations = np.array([0.1, 0.45, 1.7, 0.0, 2.75])
    n, draws = 5, 4000
    rng = np.random.default_rng(7)
    counts = np.zeros(expectations.size)
    for _ in range(draws):
        counts += np.bincount(ga.stochastic_universal_sampling(expectations, n, rng), minlength=expectations.size)
    frac = expectations - np.floor(expectations)  # copies = floor + Bernoulli(frac)
    bound = SIGMAS * np.sqrt(frac * (1 - frac) / draws) + 1e-12
    assert np.all(np.abs(counts / draws - expectations) <= bound)


def test_rank_expectations_follow_matlab_fitscalingrank():
    costs = np.array([3.0, -1.0, 10.0, 0.5, 7.0])
    n = 8
    expectations = ga.rank_expectations(costs, n)
    ranks = np.empty(costs.size)
    ranks[np.argsort(costs)] = np.arange(1, costs.size + 1)
    weights = 1.0 / np.sqrt(ranks)
    np.testing.assert_allclose(expectations, n * weights / weights.sum(), rtol=1e-14)


@pytest.mark.parametrize("seed", range(20))
def test_rank_expectations_sum_to_n_and_decrease_with_cost(seed):
    rng = np.random.default_rng(seed)
    size = int(rng.integers(2, 60))
    costs = rng.normal(size=size)
    costs[rng.integers(size, size=3)] = costs[0]  # some ties
    n = int(rng.integers(1, 100))
    expectations = ga.rank_expectations(costs, n)
    assert expectations.sum() == pytest.approx(n, rel=1e-12)
    order = np.argsort(costs, kind="stable")
    assert np.all(np.diff(expectations[order]) <= 1e-15)
    assert np.all(np.diff(expectations[order])[np.diff(costs[order]) > 0] < 0)
    tied = costs == costs[0]
    np.testing.assert_allclose(expectations[tied], expectations[0], rtol=1e-14)


def test_non_finite_costs_get_the_smallest_expectation():
    costs = np.array([1e300, np.nan, -5.0, np.inf, 0.0, -np.inf])
    expectations = ga.rank_expectations(costs, 6)
    bad = ~np.isfinite(costs)
    assert expectations[bad].max() < expectations[~bad].min()
    assert expectations.sum() == pytest.approx(6.0)


# ---------------------------------------------------------------------------------------------
# Variation
# ---------------------------------------------------------------------------------------------


def test_uniform_crossover_rates_with_complementary_parents():
    n_pairs, length, p = 4000, 64, 0.6
    parents = np.zeros((2 * n_pairs, length), dtype=np.uint8)
    parents[1::2] = 1
    children = ga.uniform_crossover(parents, p, 11)
    assert children.shape == parents.shape and children.dtype == np.uint8
    assert np.all(children[0::2] + children[1::2] == 1)  # bits are swapped, never lost
    crossed = children[0::2].any(axis=1)  # misses a crossed pair only with prob. 2**-64
    assert abs(crossed.mean() - p) <= binomial_bound(n_pairs, p)
    swapped = children[0::2][crossed]
    assert abs(swapped.mean() - 0.5) <= binomial_bound(swapped.size, 0.5)
    assert np.array_equal(parents[1::2], np.ones((n_pairs, length)))  # input untouched


def test_uniform_crossover_edge_probabilities_and_odd_count():
    rng = np.random.default_rng(3)
    parents = rng.integers(0, 2, size=(7, 40)).astype(np.uint8)
    assert np.array_equal(ga.uniform_crossover(parents, 0.0, rng), parents)
    children = ga.uniform_crossover(parents, 1.0, rng)
    assert np.array_equal(children[-1], parents[-1])  # odd count: last one copied
    pair_sums = children[:-1:2].astype(int) + children[1::2]
    assert np.array_equal(pair_sums, parents[:-1:2].astype(int) + parents[1::2])
    assert not np.array_equal(children[:-1], parents[:-1])


def test_bit_flip_mutation_rate():
    p = 0.001
    bits = np.random.default_rng(5).integers(0, 2, size=(1000, 784)).astype(np.uint8)
    mutated = ga.bit_flip_mutation(bits, p, 9)
    flipped = mutated != bits
    assert abs(flipped.mean() - p) <= binomial_bound(bits.size, p)
    assert mutated.dtype == np.uint8 and set(np.unique(mutated)) <= {0, 1}
    rows = flipped.sum(axis=1)  # flips spread over the rows like Binomial(784, p)
    assert rows.max() <= 6


def test_bit_flip_mutation_edge_probabilities():
    bits = np.random.default_rng(1).integers(0, 2, size=(5, 33)).astype(np.uint8)
    assert np.array_equal(ga.bit_flip_mutation(bits, 0.0, 0), bits)
    assert np.array_equal(ga.bit_flip_mutation(bits, 1.0, 0), 1 - bits)


# ---------------------------------------------------------------------------------------------
# Driver
# ---------------------------------------------------------------------------------------------


def noisy_rastrigin(seed: int):
    noise = np.random.default_rng(seed)

    def cost(x: np.ndarray) -> np.ndarray:
        clean = 10 * x.shape[1] + np.sum(x**2 - 10 * np.cos(2 * np.pi * x), axis=1)
        return clean + noise.normal(scale=2.0, size=x.shape[0])

    return cost


@pytest.mark.parametrize(
    "options",
    [
        ga.GAOptions(),
        ga.GAOptions(population_size=21, elite_count=0, max_generations=30),
        ga.GAOptions(population_size=7, elite_count=3, n_bits=5, mutation_probability=0.05),
    ],
)
def test_best_never_gets_worse(options):
    lower, upper = np.full(6, -5.12), np.full(6, 5.12)
    recorder = Recorder(noisy_rastrigin(4))
    result = ga.minimize(recorder, lower, upper, options=options, seed=2)

    assert result.history.shape == (result.generations + 1,)
    assert np.all(np.diff(result.history) <= 0)
    # history steps through exactly the running minimum of every cost evaluated (a generation
    # whose children all copy their parents calls no cost): the best is never lost
    running_min = np.minimum.accumulate([values.min() for _, values in recorder.calls])
    assert result.history[0] == running_min[0]
    np.testing.assert_array_equal(np.unique(result.history), np.unique(running_min))
    # and the result is that very individual, bits and values
    candidates = np.concatenate([x for x, _ in recorder.calls])
    costs = np.concatenate([values for _, values in recorder.calls])
    assert result.cost == costs.min()
    assert np.array_equal(result.x, candidates[np.argmin(costs)])
    assert np.array_equal(result.bits, ga.encode(result.x, lower, upper, options.n_bits))
    assert result.success


def test_elite_bits_are_copied_unchanged():
    lower, upper = np.zeros(3), np.ones(3)
    target = np.array([0.2, 0.9, 0.5])
    base = ga.minimize(sphere(target), lower, upper, seed=8, options=ga.GAOptions(n_bits=6))
    # One more generation from the same state can only keep or improve the best code.
    for generations in range(1, 8):
        options = ga.GAOptions(n_bits=6, max_generations=generations)
        shorter = ga.minimize(sphere(target), lower, upper, seed=8, options=options)
        np.testing.assert_array_equal(shorter.history, base.history[: generations + 1])
        if base.history[generations] == base.history[generations - 1]:
            previous = ga.GAOptions(n_bits=6, max_generations=generations - 1)
            before = ga.minimize(sphere(target), lower, upper, seed=8, options=previous)
            assert np.array_equal(shorter.bits, before.bits)


def test_cost_is_called_once_per_generation_with_new_individuals():
    lower, upper = np.full(98, 0.0), np.full(98, 5000.0)
    recorder = Recorder(lambda x: np.linalg.norm(x - 1234.0, axis=1))
    result = ga.minimize(recorder, lower, upper, seed=1)
    sizes = [x.shape[0] for x, _ in recorder.calls]
    assert sizes[0] == 50
    assert len(recorder.calls) <= result.generations + 1
    assert all(1 <= m <= 49 for m in sizes[1:])
    assert all(x.shape[1] == 98 for x, _ in recorder.calls)
    assert result.n_evaluations == sum(sizes)
    assert result.generations == 50
    assert result.x.shape == (98,) and result.bits.shape == (784,)
    assert result.bits.dtype == np.uint8


def test_same_seed_same_result_bit_for_bit():
    lower, upper = np.full(8, -5.12), np.full(8, 5.12)
    runs = [
        ga.minimize(noisy_rastrigin(0), lower, upper, seed=seed) for seed in (42, 42, np.random.default_rng(42), 43)
    ]
    first = runs[0]
    for again in runs[1:3]:
        assert np.array_equal(again.bits, first.bits)
        assert np.array_equal(again.x, first.x)
        assert np.array_equal(again.history, first.history)
        assert again.n_evaluations == first.n_evaluations
    assert not np.array_equal(runs[3].history, first.history)


@pytest.mark.parametrize("seed", range(5))
def test_sphere_beats_random_search(seed):
    lower, upper = -np.ones(10), np.ones(10)
    rng = np.random.default_rng(100 + seed)
    target = rng.uniform(-0.9, 0.9, 10)
    result = ga.minimize(sphere(target), lower, upper, seed=seed)
    random_best = sphere(target)(rng.uniform(-1, 1, (result.n_evaluations, 10))).min()
    assert result.cost < 0.5 * random_best
    assert result.cost < 0.25 * result.history[0]


def test_one_gene_converges_to_the_quantisation_grid():
    """With 256 codes the GA lands on the grid point nearest the optimum (most seeds)."""
    lower, upper = np.array([-1.0]), np.array([1.0])
    step = 2.0 / 255
    hits = 0
    for seed in range(20):
        target = np.random.default_rng(seed).uniform(-0.9, 0.9, 1)
        result = ga.minimize(sphere(target), lower, upper, seed=seed)
        hits += abs(result.x[0] - target[0]) <= step / 2
    assert hits >= 14


def test_optimum_on_a_bound_is_reached_exactly():
    lower, upper = np.array([-1.0, 0.0]), np.array([1.0, 3.0])
    result = ga.minimize(sphere(upper), lower, upper, seed=0)
    assert np.array_equal(result.x, upper) and result.cost == 0.0


def test_initial_seed_with_optimum_gives_its_cost_at_generation_zero():
    lower, upper = -np.ones(10), np.ones(10)
    target = ga.decode(ga.encode(np.linspace(-0.7, 0.8, 10), lower, upper), lower, upper)
    others = np.random.default_rng(0).uniform(-1, 1, (3, 10))
    result = ga.minimize(sphere(target), lower, upper, seed=0, initial=np.vstack([others, target]))
    assert result.history[0] == 0.0 and result.cost == 0.0
    assert np.array_equal(result.x, target)
    single = ga.minimize(sphere(target), lower, upper, seed=1, initial=target)
    assert single.history[0] == 0.0


def test_stall_generations_stop_early():
    options = ga.GAOptions(stall_generations=5)
    result = ga.minimize(lambda x: np.ones(x.shape[0]), np.zeros(4), np.ones(4), options=options)
    assert result.generations == 5 < options.max_generations
    assert result.history.shape == (6,)
    assert "stall" in result.reason and result.success


def test_zero_generations_evaluates_only_the_initial_population():
    options = ga.GAOptions(max_generations=0, population_size=10)
    result = ga.minimize(sphere(np.zeros(2)), -np.ones(2), np.ones(2), options=options, seed=0)
    assert result.generations == 0 and result.n_evaluations == 10
    assert result.history.shape == (1,)


def test_non_finite_costs_are_never_best():
    def cost(x: np.ndarray) -> np.ndarray:
        values = np.sum(x**2, axis=1)
        values[x[:, 0] < 0.5] = np.inf  # the true optimum region is infinite (a NaN is refused)
        values[x[:, 1] < -0.5] = -np.inf
        return values

    result = ga.minimize(cost, -np.ones(2), np.ones(2), seed=3)
    assert np.isfinite(result.cost) and result.success
    assert result.x[0] >= 0.5 and result.x[1] >= -0.5
    assert np.all(np.isfinite(result.history))


def test_all_non_finite_costs_report_failure():
    result = ga.minimize(
        lambda x: np.full(x.shape[0], np.inf),  # every candidate unusable (a NaN is refused)
        np.zeros(2),
        np.ones(2),
        seed=0,
        options=ga.GAOptions(max_generations=3),
    )
    assert not result.success and result.cost == np.inf
    assert "finite" in result.reason


# ---------------------------------------------------------------------------------------------
# Errors
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("n_bits", 0),
        ("n_bits", 33),
        ("n_bits", 8.0),
        ("population_size", 1),
        ("max_generations", -1),
        ("crossover_probability", 1.5),
        ("crossover_probability", float("nan")),
        ("mutation_probability", -0.001),
        ("elite_count", 50),
        ("elite_count", -1),
        ("stall_generations", 0),
        ("population_size", True),
    ],
)
def test_bad_options_name_the_field(field, value):
    with pytest.raises(InputError, match=field):
        ga.GAOptions(**{field: value})


@pytest.mark.parametrize(
    ("lower", "upper", "field"),
    [
        (np.zeros((2, 2)), np.ones((2, 2)), "lower"),
        (np.zeros(0), np.ones(0), "lower"),
        (np.zeros(3), np.ones(2), "upper"),
        (np.array([0.0, np.nan]), np.ones(2), "lower"),
        (np.zeros(2), np.array([1.0, np.inf]), "upper"),
        (np.array([0.0, 2.0]), np.ones(2), "lower"),
    ],
)
def test_bad_bounds_name_the_field(lower, upper, field):
    with pytest.raises(InputError, match=field):
        ga.minimize(sphere(np.zeros(2)), lower, upper, seed=0)


@pytest.mark.parametrize(
    "bad_cost",
    [
        lambda x: np.zeros((x.shape[0], 1)),
        lambda x: np.zeros(x.shape[0] - 1),
        lambda x: 0.0,
    ],
)
def test_cost_of_wrong_shape_is_rejected(bad_cost):
    with pytest.raises(InputError, match=r"cost.*shape \(50,\)"):
        ga.minimize(bad_cost, np.zeros(2), np.ones(2), seed=0)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"initial": np.zeros((2, 3))}, "initial"),
        ({"initial": np.zeros((51, 2))}, "initial"),
        ({"initial": np.full((1, 2), np.nan)}, "initial"),
        ({"seed": "abc"}, "seed"),
        ({"seed": -1}, "seed"),
        ({"options": {"n_bits": 8}}, "options"),
    ],
)
def test_bad_minimize_arguments_name_the_field(kwargs, field):
    with pytest.raises(InputError, match=field):
        ga.minimize(sphere(np.zeros(2)), np.zeros(2), np.ones(2), **kwargs)


def test_bad_operator_arguments_raise_input_error():
    rng = np.random.default_rng(0)
    with pytest.raises(InputError, match="bits"):
        ga.decode(np.full(8, 2), [0.0], [1.0])
    with pytest.raises(InputError, match="bits"):
        ga.decode(np.zeros(7), [0.0], [1.0])
    with pytest.raises(InputError, match="values"):
        ga.encode(np.zeros(3), np.zeros(2), np.ones(2))
    with pytest.raises(InputError, match="expectations"):
        ga.stochastic_universal_sampling([0.0, 0.0], 2, rng)
    with pytest.raises(InputError, match="expectations"):
        ga.stochastic_universal_sampling([1.0, -0.5], 2, rng)
    with pytest.raises(InputError, match="probability"):
        ga.uniform_crossover(np.zeros((2, 4)), 2.0, rng)
    with pytest.raises(InputError, match="parents"):
        ga.uniform_crossover(np.zeros(4), 0.5, rng)
    with pytest.raises(InputError, match="probability"):
        ga.bit_flip_mutation(np.zeros(4), -1.0, rng)
    with pytest.raises(InputError, match="costs"):
        ga.rank_expectations(np.zeros((2, 2)), 2)
    with pytest.raises(InputError, match="n"):
        ga.rank_expectations(np.zeros(2), -1)
