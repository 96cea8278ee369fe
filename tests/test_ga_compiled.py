"""The compiled genetic algorithm of switching control (``model/csrc/ga.c``).

Each operator is held to the readable NumPy reference (:mod:`vgtarm.ga`) given the same random
draws; the compiled generator and operators are checked for the distributions they promise; the
GA's cheaper predictions are held to the exact one; and whole runs are reproducible per seed.
"""

from __future__ import annotations

import math
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pytest

import vgtarm
from vgtarm import ga
from vgtarm.control import ComputedForceControl, SwitchingControl
from vgtarm.ga import GAOptions
from vgtarm.model import compiling
from vgtarm.model.closedloop import PREDICTIONS, ClosedLoopDriver, bit_words, pack_bits, unpack_bits
from vgtarm.model.compiled import CompiledBackend, InterpretedBackend, build_functions
from vgtarm.model.interface import ffi
from vgtarm.simulation import ExternalForce, JointReference, simulate
from vgtarm.simulation.engines import compiled_ga
from vgtarm.simulation.simulator import loop_arrays

from .conftest import assert_close
from .test_ga import SIGMAS, binomial_bound

AMPLITUDE = np.array([0.01, 0.008, -0.006, 0.007, -0.009, 0.005, 0.3])


@pytest.fixture(scope="module")
def lib(robot):
    if not isinstance(robot.backend, CompiledBackend):
        pytest.skip("no C compiler: the compiled GA is not built")
    return robot.backend.library


def _d(a):
    return ffi().cast("double *", a.ctypes.data)


def _u(a):
    return ffi().cast("uint64_t *", a.ctypes.data)


def _l(a):
    return ffi().cast("long *", a.ctypes.data)


def reference(robot, duration=0.3, dt=1e-3) -> JointReference:
    t = np.arange(0.0, duration + 1e-9, dt)
    wt = 6.0 * t[:, None]
    return JointReference(
        t, robot.parameters.home + AMPLITUDE * np.sin(wt), AMPLITUDE * 6 * np.cos(wt), -AMPLITUDE * 36 * np.sin(wt)
    )


class DrawsRng:
    """A stand-in for numpy's Generator that hands the NumPy operators given draws."""

    def __init__(self, uniforms=(), integers=None, binomial=None, choice=None):
        self.uniforms = list(uniforms)
        self.integers_value, self.binomial_value, self.choice_value = integers, binomial, choice

    def random(self, size=None):
        if size is None:
            return self.uniforms.pop(0)
        out, self.uniforms = np.array(self.uniforms[:size]), self.uniforms[size:]
        return out

    def integers(self, low, high, size, dtype):
        return self.integers_value

    def binomial(self, n, p):
        return self.binomial_value

    def choice(self, n, size, replace):
        return self.choice_value


# ---------------------------------------------------------------------------------------------
# Operators against the NumPy reference, given the same draws
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("n_bits", [1, 5, 8, 12, 16])
def test_decode_matches_numpy_bit_for_bit(lib, n_bits):
    rng = np.random.default_rng(n_bits)
    n_genes, rows = 13, 40
    lower = rng.uniform(-5, 5, n_genes)
    upper = lower + rng.uniform(0, 10, n_genes)
    upper[3] = lower[3]
    bits = rng.integers(0, 2, size=(rows, n_genes * n_bits)).astype(np.uint8)
    bits[0] = 1  # every gene at its upper bound
    bits[1] = 0
    words = bit_words(n_genes * n_bits)
    packed = pack_bits(bits, words)
    np.testing.assert_array_equal(unpack_bits(packed, n_genes * n_bits), bits)
    settings = ffi().new("vgt_ga_settings *", {"n_genes": n_genes, "n_bits": n_bits, "words": words})
    genes = np.empty((rows, n_genes))
    lib.vgt_ga_decode(settings, rows, _u(packed), _d(lower), _d(upper), _d(genes))
    np.testing.assert_array_equal(genes, ga.decode(bits, lower, upper, n_bits))


@pytest.mark.parametrize("seed", range(3))
def test_the_predictions_single_precision_decode_is_numpys_rounded_to_float(lib, seed):
    """The prediction decodes 8-bit genes in float arithmetic (no table look-ups): both code paths
    give the same floats, each within a few float ulp (of the larger bound) of NumPy's double
    decode, and the bounds exactly at the end codes. Rows that are not a multiple of the block exercise the
    unused lanes."""
    rng = np.random.default_rng(300 + seed)
    n_genes, rows = int(rng.integers(1, 120)), int(rng.integers(1, 30))
    lower = rng.uniform(-5e4, 5e4, n_genes) * rng.choice([1e-3, 1.0], n_genes)
    upper = lower + rng.uniform(0, 3e4, n_genes)
    upper[0] = lower[0]  # a gene with one value
    bits = rng.integers(0, 2, size=(rows, n_genes * 8)).astype(np.uint8)
    bits[0] = 1
    if rows > 1:
        bits[1] = 0
    words = bit_words(n_genes * 8)
    packed = pack_bits(bits, words)
    settings = ffi().new("vgt_ga_settings *", {"n_genes": n_genes, "n_bits": 8, "words": words})
    out = {}
    for vector in (0, 1):
        out[vector] = np.full((rows, n_genes), np.nan, dtype=np.float32)
        status = lib.vgt_ga_decode_single(
            settings, rows, _u(packed), _d(lower), _d(upper), vector, ffi().cast("float *", out[vector].ctypes.data)
        )
        assert status == 0
    np.testing.assert_array_equal(out[0], out[1])
    expected = ga.decode(bits, lower, upper, 8).astype(np.float32)
    ulp = np.spacing(np.maximum(np.abs(lower), np.abs(upper)).astype(np.float32))  # of the gene's range
    assert np.all(np.abs(out[0].astype(np.float64) - expected) <= 4 * ulp)
    np.testing.assert_array_equal(out[0][0], upper.astype(np.float32))
    if rows > 1:
        np.testing.assert_array_equal(out[0][1], lower.astype(np.float32))
    settings.n_bits = 5
    assert lib.vgt_ga_decode_single(settings, rows, _u(packed), _d(lower), _d(upper), 1, ffi().NULL) != 0


def test_decode_inside_the_activation_matches_numpy(lib, robot):
    """The activation's 8-bit fast path: its best genes are a decoded code."""
    ref = reference(robot, duration=0.05)
    scm = SwitchingControl.with_gains(5000.0, 300.0, variant="paper", threshold=1e-9, ga=GAOptions(max_generations=3))
    compiled = _ga(robot, ref, scm)
    out = compiled.activate(1, ref.q[1] + 1e-4, ref.qd[1], seed=3)
    lower, upper = scm.bounds()
    codes = ga.encode(out.genes, lower, upper, 8)
    np.testing.assert_array_equal(ga.decode(codes, lower, upper, 8), out.genes)


@pytest.mark.parametrize("seed", range(12))
def test_rank_expectations_match_numpy(lib, seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 160))
    costs = rng.choice(rng.normal(size=n // 2 + 1), size=n)  # ties
    costs[rng.random(n) < 0.1] = np.inf
    costs[rng.random(n) < 0.05] = np.nan
    n_parents = int(rng.integers(1, 3 * n))
    out = np.empty(n)
    lib.vgt_ga_rank_expectations(n, _d(np.ascontiguousarray(costs)), n_parents, _d(out))
    # the same ranks, ties and weights; sums may differ in the last bit from NumPy's SIMD summation
    assert_close(out, ga.rank_expectations(costs, n_parents), rtol=1e-14, atol=0)


@pytest.mark.parametrize("seed", range(12))
def test_sus_matches_numpy_given_the_same_pointer(lib, seed):
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(1, 80))
    expectations = ga.rank_expectations(rng.normal(size=n), n)
    n_select = int(rng.integers(0, 2 * n + 1))
    u = float(rng.random())
    out = np.empty(n_select, dtype=np.int64)
    lib.vgt_ga_sus(n, _d(expectations), n_select, u, _l(out))
    np.testing.assert_array_equal(out, ga._sus(expectations, n_select, DrawsRng([u])))


@pytest.mark.parametrize("seed", range(6))
def test_crossover_matches_numpy_given_the_same_masks(lib, seed):
    rng = np.random.default_rng(200 + seed)
    rows, length = int(rng.integers(2, 30)), int(rng.integers(1, 300))
    parents = rng.integers(0, 2, size=(rows, length)).astype(np.uint8)
    uniforms = rng.random(rows // 2)
    crossed = uniforms < 0.6
    mask_bytes = rng.integers(0, 256, size=(int(crossed.sum()), -(-length // 8)), dtype=np.uint8)
    expected = ga._crossover(parents, 0.6, DrawsRng(uniforms, integers=mask_bytes))
    words = bit_words(length)
    packed = pack_bits(parents, words)
    masks = pack_bits(np.unpackbits(mask_bytes, axis=1, count=length), words)
    flags = np.ascontiguousarray(crossed.astype(np.uint8))
    lib.vgt_ga_crossover(words, rows, _u(packed), ffi().cast("unsigned char *", flags.ctypes.data), _u(masks))
    np.testing.assert_array_equal(unpack_bits(packed, length), expected)


def test_mutation_flips_the_same_positions_as_numpy(lib):
    rng = np.random.default_rng(5)
    rows, length = 7, 190
    bits = rng.integers(0, 2, size=(rows, length)).astype(np.uint8)
    positions = np.sort(rng.choice(rows * length, size=25, replace=False))
    expected = ga._mutate(bits, 0.01, DrawsRng(binomial=len(positions), choice=positions))
    # the compiled GA flips positions of the children block laid end to end
    words = bit_words(length)
    packed = pack_bits(bits, words)
    for p in positions:
        lib.vgt_ga_flip(words, _u(packed[p // length]), 1, _l(np.array([p % length], dtype=np.int64)))
    np.testing.assert_array_equal(unpack_bits(packed, length), expected)


# ---------------------------------------------------------------------------------------------
# The generator and the operators' distributions
# ---------------------------------------------------------------------------------------------


def test_generator_is_uniform_and_seeded(lib):
    n = 200_000
    a, b, c = np.empty(n), np.empty(n), np.empty(n)
    lib.vgt_rng_uniform(7, n, _d(a))
    lib.vgt_rng_uniform(7, n, _d(b))
    lib.vgt_rng_uniform(8, n, _d(c))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert 0.0 <= a.min() and a.max() < 1.0
    assert abs(a.mean() - 0.5) < SIGMAS * math.sqrt(1 / 12 / n)
    assert abs(a.var() - 1 / 12) < 0.002
    counts = np.histogram(a, bins=20, range=(0, 1))[0]
    assert np.all(np.abs(counts / n - 0.05) < binomial_bound(n, 0.05))
    assert abs(np.corrcoef(a[:-1], a[1:])[0, 1]) < SIGMAS / math.sqrt(n)


@pytest.mark.parametrize("p", [0.001, 0.02])
def test_mutation_positions_have_the_per_bit_distribution(lib, p):
    total, trials = 39_200, 200
    flips_per_trial, all_positions = [], []
    for seed in range(trials):
        out = np.empty(total, dtype=np.int64)
        n = ffi().new("long *")
        lib.vgt_rng_mutation_positions(seed, total, p, total, _l(out), n)
        positions = out[: n[0]]
        assert np.all(np.diff(positions) > 0) and (positions.size == 0 or (positions[0] >= 0 and positions[-1] < total))
        flips_per_trial.append(n[0])
        all_positions.append(positions)
    flips = np.array(flips_per_trial)
    mean, var = total * p, total * p * (1 - p)
    assert abs(flips.mean() - mean) < SIGMAS * math.sqrt(var / trials)
    assert 0.7 * var < flips.var() < 1.3 * var
    spread = np.histogram(np.concatenate(all_positions), bins=10, range=(0, total))[0]
    expected = flips.sum() / 10
    assert np.all(np.abs(spread - expected) < SIGMAS * math.sqrt(expected))


def test_mutation_edge_probabilities(lib):
    out = np.empty(50, dtype=np.int64)
    n = ffi().new("long *")
    lib.vgt_rng_mutation_positions(1, 50, 0.0, 50, _l(out), n)
    assert n[0] == 0
    lib.vgt_rng_mutation_positions(1, 50, 1.0, 50, _l(out), n)
    assert n[0] == 50 and list(out) == list(range(50))


# ---------------------------------------------------------------------------------------------
# Predictions
# ---------------------------------------------------------------------------------------------


def _ga(robot, ref, scm, model=None):
    model = model or robot

    arrays = loop_arrays(robot, model, ref, initial_state=(ref.q[0], ref.qd[0]))
    return compiled_ga(scm, ClosedLoopDriver(robot.backend), model, arrays, ref.dt)


@pytest.mark.parametrize("stable_scale", [0.05, 0.3])
def test_cheap_predictions_agree_with_the_exact_one(lib, robot, stable_scale):
    """Joint errors of a few tenths of a millimetre (the switching threshold's scale): the
    quadratic map is within 1e-3 relative of the exact prediction, the linear map is not as good."""
    ref = reference(robot, duration=0.1)
    scm = SwitchingControl.with_gains(
        5000.0, 300.0, variant="paper", kp_bounds=(0, 15000), kv_bounds=(0, 600), exact_above=0.0
    )
    compiled = _ga(robot, ref, scm)
    rng = np.random.default_rng(4)
    lower, upper = scm.bounds()
    genes = lower + stable_scale * rng.random((64, len(lower))) * (upper - lower)
    genes[0] = np.concatenate([scm.fixed.Kp.ravel(), scm.fixed.Kv.ravel()])
    k = 30
    q0 = ref.q[k] + rng.normal(scale=2e-4, size=7)
    qd0 = ref.qd[k] + rng.normal(scale=2e-3, size=7)
    costs = {}
    for name in PREDICTIONS:
        compiled._ga.prediction = PREDICTIONS[name]
        costs[name] = compiled.predict(k, q0, qd0, genes)
    # the exact mode is the NumPy prediction
    from vgtarm.control import predict_tip_error

    window = slice(k, k + scm.horizon + 1)
    Kp, Kv = scm.split(genes)
    tip_d = robot.tip_position(ref.q[window])
    numpy_exact = predict_tip_error(
        robot, ref.dt, q0, qd0, ref.q[window], ref.qd[window], ref.qdd[window], tip_d, Kp, Kv
    )
    finite = np.isfinite(numpy_exact)
    assert finite[0]
    assert_close(costs["exact"][finite], numpy_exact[finite], rtol=1e-12, atol=0)
    bounded = finite & (numpy_exact < 1.0)
    rel = np.abs(costs["quadratic"][bounded] - numpy_exact[bounded]) / numpy_exact[bounded]
    assert rel.max() < 1e-3, rel.max()
    assert np.abs(costs["linear"][0] - numpy_exact[0]) / numpy_exact[0] < 3e-2


def test_trust_region_falls_back_to_the_exact_map(lib, robot):
    """Candidates whose predicted joint error leaves the region get the exact map for those steps."""
    ref = reference(robot, duration=0.1)
    scm = SwitchingControl.with_gains(5000.0, 300.0, variant="paper", kp_bounds=(0, 15000), kv_bounds=(0, 600))
    compiled = _ga(robot, ref, scm)
    rng = np.random.default_rng(9)
    lower, upper = scm.bounds()
    genes = lower + rng.random((40, len(lower))) * (upper - lower)  # many unstable candidates
    k = 20
    q0, qd0 = ref.q[k] + 1e-4, ref.qd[k]
    compiled._ga.prediction = PREDICTIONS["exact"]
    exact = compiled.predict(k, q0, qd0, genes)
    compiled._ga.prediction = PREDICTIONS["quadratic"]
    compiled._ga.exact_above = 1e-12  # every step outside: the exact map everywhere
    everywhere = compiled.predict(k, q0, qd0, genes)
    # the joint errors come from the single-precision recursion: about 1e-6 relative at most
    assert_close(everywhere[np.isfinite(exact)], exact[np.isfinite(exact)], rtol=1e-5, atol=0)
    np.testing.assert_array_equal(np.isfinite(everywhere), np.isfinite(exact))
    compiled._ga.exact_above = 0.0  # never: the quadratic map even far outside its range
    far = compiled.predict(k, q0, qd0, genes)
    ok = np.isfinite(exact) & np.isfinite(far)
    assert np.max(np.abs(far[ok] - exact[ok]) / exact[ok]) > 1e-3  # why the fallback exists


def test_tip_derivatives_are_computed_in_c_for_the_rows_a_window_needs(lib, robot):
    """The GA computes a window's tip offsets, Jacobians and Hessians row by row when first needed:
    only those rows, equal to the model's batch evaluation (another route into the same
    generated functions), and not again for an overlapping window."""
    ref = reference(robot, duration=0.2)
    scm = SwitchingControl.with_gains(5000.0, 300.0, variant="paper", ga=GAOptions(max_generations=2))
    compiled = _ga(robot, ref, scm)
    k, h = 30, scm.horizon
    compiled.activate(k, ref.q[k] + 1e-4, ref.qd[k], seed=1)
    window = np.arange(k, k + h + 1)
    np.testing.assert_array_equal(np.flatnonzero(compiled._ready), window)
    q_d = ref.q[window]
    np.testing.assert_array_equal(compiled._arrays["J_d"][window], robot.tip_jacobian(q_d))
    np.testing.assert_array_equal(compiled._arrays["H_d"][window], robot.tip_hessian(q_d))
    tip_d = compiled._arrays["tip_d"][window]
    assert_close(compiled._arrays["tip_offset"][window], tip_d - robot.tip_position(q_d), rtol=0, atol=1e-15)
    compiled._arrays["J_d"][k] = np.nan  # computed once: a ready row is not recomputed
    compiled.activate(k + 5, ref.q[k + 5] + 1e-4, ref.qd[k + 5], seed=1)
    np.testing.assert_array_equal(np.flatnonzero(compiled._ready), np.arange(k, k + 5 + h + 1))
    assert np.isnan(compiled._arrays["J_d"][k]).all()


def test_trust_region_counts_only_the_joints_that_move_the_tip(lib, robot):
    """The twist does not move the tip, so the tip map is exact in it: a large twist error alone
    keeps a candidate inside the region (the same cost as the map without a region, bit for bit),
    and the cost still agrees with the exact prediction."""
    ref = reference(robot, duration=0.1)
    scm = SwitchingControl.with_gains(
        5000.0, 300.0, variant="paper", kp_bounds=(0, 15000), kv_bounds=(0, 600), exact_above=1e-3
    )
    compiled = _ga(robot, ref, scm)
    n = len(ref.q[0])
    rng = np.random.default_rng(12)
    diagonal = np.zeros((6, 2, n, n))  # decoupled gains: the twist's error stays in the twist
    for c in range(6):
        for m in range(2):
            diagonal[c, m][np.diag_indices(n)] = rng.uniform(0.2, 1.0, n) * (5000.0 if m == 0 else 300.0)
    genes = diagonal.reshape(6, -1)
    k = 20
    twist = n - 1
    assert np.all(robot.tip_jacobian(ref.q[k : k + 21])[:, :, twist] == 0.0)
    q0 = ref.q[k].copy()
    q0[twist] += 0.3  # rad: far outside a 1 mm region if it counted
    inside = compiled.predict(k, q0, ref.qd[k], genes)
    compiled._ga.exact_above = 0.0
    never = compiled.predict(k, q0, ref.qd[k], genes)
    np.testing.assert_array_equal(inside, never)
    compiled._ga.prediction = PREDICTIONS["exact"]
    exact = compiled.predict(k, q0, ref.qd[k], genes)
    assert_close(inside, exact, rtol=1e-4, atol=1e-12)


# ---------------------------------------------------------------------------------------------
# Whole activations and runs
# ---------------------------------------------------------------------------------------------


def test_activation_is_reproducible_per_seed_and_never_worse_than_the_seeded_gains(lib, robot):
    ref = reference(robot, duration=0.1)
    scm = SwitchingControl.with_gains(5000.0, 300.0, variant="paper")
    compiled = _ga(robot, ref, scm)
    q0, qd0 = ref.q[10] + 3e-4, ref.qd[10] - 1e-3
    a = compiled.activate(10, q0, qd0, seed=11)
    b = compiled.activate(10, q0, qd0, seed=11)
    c = compiled.activate(10, q0, qd0, seed=12)
    np.testing.assert_array_equal(a.genes, b.genes)
    assert a.best_cost == b.best_cost and a.evaluations == b.evaluations
    assert not np.array_equal(a.genes, c.genes)
    assert a.best_cost <= a.seeded_cost and a.generations == 50
    assert 50 < a.evaluations <= 50 * 51


@pytest.mark.parametrize("prediction", ["quadratic", "exact"])
def test_any_thread_count_gives_the_same_activation_bit_for_bit(lib, robot, prediction):
    """The prediction's blocks are shared out between threads; every candidate's cost depends on
    its own lane only, so 1, 2 or 3 threads give the same activation, counters included."""
    ref = reference(robot, duration=0.1)
    scm = SwitchingControl.with_gains(5000.0, 300.0, variant="paper", prediction=prediction)
    compiled = _ga(robot, ref, scm)
    q0, qd0 = ref.q[10] + 3e-4, ref.qd[10] - 1e-3
    runs = []
    for threads in (1, 2, 3):
        compiled._ga.threads = threads
        runs.append(compiled.activate(10, q0, qd0, seed=5))
    for other in runs[1:]:
        np.testing.assert_array_equal(other.genes, runs[0].genes)
        assert (other.best_cost, other.evaluations, other.exact_candidates, other.exact_steps) == (
            runs[0].best_cost,
            runs[0].evaluations,
            runs[0].exact_candidates,
            runs[0].exact_steps,
        )


def test_ga_threads_come_from_the_environment(monkeypatch):
    from vgtarm.errors import ConfigError
    from vgtarm.model.closedloop import MAX_GA_THREADS, ga_threads

    monkeypatch.setenv("VGTARM_THREADS", "3")
    assert ga_threads() == 3
    monkeypatch.delenv("VGTARM_THREADS")
    assert 1 <= ga_threads() <= MAX_GA_THREADS
    for bad in ("0", "two", "-1", "1e9"):
        monkeypatch.setenv("VGTARM_THREADS", bad)
        with pytest.raises(ConfigError, match="VGTARM_THREADS"):
            ga_threads()


def test_a_ga_whose_best_is_the_seeded_gains_returns_them_exactly(lib, robot):
    """With a one-step horizon no candidate can do better than the seeded fixed gains."""
    ref = reference(robot, duration=0.05)
    scm = SwitchingControl.with_gains(4321.0, 123.0, variant="paper", horizon=1)
    compiled = _ga(robot, ref, scm)
    out = compiled.activate(5, ref.q[5] + 2e-4, ref.qd[5], seed=1)
    seeded = ga.decode(scm.initial_bits(), *scm.bounds())[0]
    np.testing.assert_array_equal(out.genes, seeded)
    assert out.best_cost == out.seeded_cost


def test_compiled_ga_finds_gains_as_good_as_the_numpy_ga(lib, robot):
    """Same problem, the paper's settings, ten seeds each: the two GAs reach the same quality."""
    ref = reference(robot, duration=0.1)
    scm = SwitchingControl.with_gains(5000.0, 300.0, variant="paper", prediction="exact")
    compiled = _ga(robot, ref, scm)
    k, q0, qd0 = 10, ref.q[10] + 3e-4, ref.qd[10] - 2e-3
    window = slice(k, k + scm.horizon + 1)
    predict = ClosedLoopDriver(robot.backend).ga_predictor(
        robot.parameter_vector,
        ref.dt,
        q0,
        qd0,
        ref.q[window],
        ref.qd[window],
        ref.qdd[window],
        robot.tip_position(ref.q[window]),
    )
    c_best = [compiled.activate(k, q0, qd0, seed=s).best_cost for s in range(10)]
    n_best = [scm.tune(predict, np.random.default_rng(s))[1].cost for s in range(10)]
    seeded = float(predict(scm.fixed.Kp[None], scm.fixed.Kv[None])[0])
    assert max(c_best) <= seeded and max(n_best) <= seeded
    spread = np.std(n_best) + np.std(c_best)
    assert abs(np.mean(c_best) - np.mean(n_best)) < 3 * spread + 1e-3 * seeded


def test_switching_control_run_is_reproducible_bit_for_bit(lib, robot):
    ref = reference(robot, duration=0.2)
    scm = SwitchingControl.with_gains(5000.0, 300.0, variant="paper", threshold=5e-5)
    runs = [simulate(robot, ref, scm, external_force=ExternalForce(), seed=s) for s in (3, 3, 4)]
    assert runs[0].activations
    for name in ("q", "qd", "effort", "tip_error"):
        np.testing.assert_array_equal(getattr(runs[0], name), getattr(runs[1], name))
    assert not np.array_equal(runs[0].q, runs[2].q)
    summary = runs[0].summary()
    assert 0 < summary["ga_activation_time_median_s"] <= summary["ga_activation_time_p99_s"]


@pytest.mark.parametrize(("sensing", "threshold"), [(False, 1e-9), (True, 1.2e-4)])
def test_the_ga_inside_the_compiled_loop_gives_the_per_activation_run_bit_for_bit(
    lib, robot, monkeypatch, sensing, threshold
):
    """One compiled call per chunk (the GA called by the loop) against one call per activation
    from Python: the same states, efforts, modes and activation records, to the last bit, with
    the tool force, the observer and sensing where asked, up to the last sample of the path."""
    from vgtarm.simulation import engines

    ref = reference(robot, duration=0.12)
    scm = SwitchingControl.with_gains(5000.0, 300.0, variant="paper", threshold=threshold)
    options = dict(observer="momentum", encoder_resolution=1e-6, velocity_filter_hz=100.0) if sensing else {}
    runs = []
    for in_loop in (True, False):
        monkeypatch.setattr(engines, "GA_IN_LOOP", in_loop)
        runs.append(simulate(robot, ref, scm, external_force=ExternalForce(), seed=7, **options))
    inside, outside = runs
    assert len(inside.activations) > 5
    if threshold < 1e-6:  # every sample above it, the last one too (it keeps the fixed gains)
        assert len(inside.activations) == len(ref.t) - 1  # all but the first (on the path)
        assert inside.activations[-1].sample == len(ref.t) - 1 and inside.activations[-1].generations == 0
    else:  # fixed gains and GA gains alternate
        assert len(inside.activations) < len(ref.t) - 10
    for name in ("q", "qd", "effort", "tip_error", "mode"):
        np.testing.assert_array_equal(getattr(inside, name), getattr(outside, name))
    for a, b in zip(inside.activations, outside.activations, strict=True):
        assert (a.sample, a.generations, a.evaluations, a.best_fitness, a.fixed_gains_fitness) == (
            b.sample,
            b.generations,
            b.evaluations,
            b.best_fitness,
            b.fixed_gains_fitness,
        )
        assert a.error_after_m == b.error_after_m or (np.isnan(a.error_after_m) and np.isnan(b.error_after_m))


def test_the_switching_loop_in_slices_is_bit_for_bit_the_loop_in_one_call(lib, robot):
    """Pauses between samples and inside an activation's sample (rk4, three sub-steps, a budget
    of one or two units a call) resume exactly: the same states and activation records."""
    from vgtarm.model.closedloop import LoopSettings

    ref = reference(robot, duration=0.03)
    scm = SwitchingControl.with_gains(5000.0, 300.0, variant="paper", threshold=2e-5)
    n = len(ref.t)
    settings = LoopSettings(
        dt=ref.dt,
        integrator="rk4",
        substeps=3,
        cutting=True,
        cutting_force=20.0,
        cutting_speed=1e-6,
        threshold=scm.threshold,
        limit_tolerance=0.05,
    )
    unswitched = LoopSettings(**{**settings.__dict__, "threshold": 0.0})
    runs = []
    for budget in (10**12, 2, 1):
        arrays = loop_arrays(robot, robot, ref, np.random.default_rng(1).normal(scale=5.0, size=(n, 3)))
        driver = ClosedLoopDriver(robot.backend, slice_budget=budget)
        compiled = compiled_ga(scm, driver, robot, arrays, ref.dt)
        compiled.bind_switching(np.random.default_rng(2).integers(0, 2**63, size=n, dtype=np.int64))
        gains = scm.gains
        status, stop = driver.simulate_switching(settings, unswitched, arrays, gains.Kp, gains.Kv, compiled, 0, n)
        assert (status, stop) == (0, n)
        count = int(compiled.switching.count)
        runs.append((arrays, compiled.records(0, count), driver.slices))
    (whole, records, calls) = runs[0]
    assert len(records["sample"]) > 5
    for arrays, sliced_records, sliced_calls in runs[1:]:
        assert sliced_calls > max(n, calls)  # a pause inside (nearly) every sample
        for name in ("q", "qd", "F", "f_ext", "tip", "error"):
            np.testing.assert_array_equal(getattr(arrays, name), getattr(whole, name), err_msg=name)
        for name in ("sample", "generations", "evaluations", "best_cost", "seeded_cost"):
            np.testing.assert_array_equal(sliced_records[name], records[name], err_msg=name)


def test_switching_control_without_a_compiler_runs_the_numpy_ga(robot, caplog):
    """The interpreter fallback (no C compiler) still runs switching control, slowly."""
    slow = vgtarm.Robot(robot.parameters, InterpretedBackend(build_functions()))
    ref = reference(robot, duration=0.02)
    scm = SwitchingControl.with_gains(5000.0, 300.0, variant="paper", threshold=1e-9, ga=GAOptions(max_generations=2))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        run = simulate(slow, ref, scm, initial_state=(ref.q[0] + 1e-4, ref.qd[0]))
    assert run.metadata["backend"] == "interpreted" and run.activations
    assert all(a.best_fitness <= a.fixed_gains_fitness for a in run.activations)
    cfc = simulate(slow, ref, ComputedForceControl.with_gains(5000.0, 300.0))
    assert cfc.success


def test_bad_prediction_settings_are_named():
    with pytest.raises(vgtarm.InputError, match="prediction = 'cubic'"):
        SwitchingControl.with_gains(1.0, 1.0, variant="paper", prediction="cubic")
    with pytest.raises(vgtarm.InputError, match="exact_above"):
        SwitchingControl.with_gains(1.0, 1.0, variant="paper", exact_above=-1.0)


#: The kernel's C test (tests/csrc/ga_kernel_lanes.c) and the GA's one C file it includes.
KERNEL_TEST = Path(__file__).resolve().parent / "csrc" / "ga_kernel_lanes.c"
GA_CSRC = Path(compiling.__file__).resolve().parent / "csrc"


@pytest.mark.parametrize("level", ["-O2", "-O3"])
def test_the_kernels_vector_lanes_equal_its_plain_c99_lanes(level, tmp_path):
    """The prediction kernel and the safe variant's repair of vgt_ga.h built as the model libraries
    build them (-O2: the symbolic library, -O3: the recursive one; no contraction) for every x86-64
    level this CPU has equal the plain C99 arrays' lane for lane, bit for bit, for 1 to 21 joints.
    GCC 12 at -O3 for AVX-512 once compiled a branch on a joint's moves flag into a multiply masked
    to lane 0: the six-module stack's (21 joints, a count known at run time) recursive and symbolic
    runs then parted."""
    compiler = compiling.find_compiler()
    if compiler is None:
        pytest.skip("no C compiler")
    flags = ["-std=c99", level, "-ffp-contract=off", "-I", str(GA_CSRC)]
    plain, program = tmp_path / "plain.o", tmp_path / "kernel_lanes"
    subprocess.run([compiler, *flags, "-DPLAIN_KERNEL", "-c", "-o", str(plain), str(KERNEL_TEST)], check=True)
    subprocess.run([compiler, *flags, "-o", str(program), str(KERNEL_TEST), str(plain), "-lm"], check=True)
    done = subprocess.run([str(program)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.endswith("0 differences\n"), done.stdout[-2000:]
