"""The safe variant of switching control (issue 23): admission of gains on the discrete loop.

The admission (``control/safety.py`` for the interval, ``csrc/ga.c`` for the test) is held to an
independent computation: NumPy's eigenvalues of the full ``4n x 4n`` loop matrix, and a
simulation of the linear error dynamics; the compiled GA never admits a candidate whose loop
has a pole outside the margin circle; runs are reproducible per seed; a held set whose seen error
rises above its value at the switch is dropped at that period (the rule written out in
``dropped_at``, applied to recorded errors); the safe variant is the library's default, and the
paper's, asked for by name, is held bit for bit by ``tests/test_ga_compiled.py``.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from vgtarm.control import SwitchingControl
from vgtarm.control.safety import admitted_interval, damping_table, loop_matrix, spectral_radius
from vgtarm.control.scm import dropped_at
from vgtarm.errors import InputError, SimulationError
from vgtarm.experiment.cases import case_study, joint_reference, run_case
from vgtarm.model.closedloop import ClosedLoopDriver, LoopSettings
from vgtarm.model.compiled import CompiledBackend
from vgtarm.simulation import simulate
from vgtarm.simulation.engines import compiled_ga
from vgtarm.simulation.scenario import Scenario
from vgtarm.simulation.simulator import drive, loop_arrays, prepare

DT = 1e-3
FILTER = math.exp(-2.0 * math.pi * 100.0 * DT)  # the default 100 Hz velocity filter
KV = 600.0  # case 2's damping
RADIUS = 0.99
MODEL_ERROR = 0.1


def _random_symmetric(rng: np.random.Generator, eigenvalues: np.ndarray) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(len(eigenvalues), len(eigenvalues))))
    return (q * eigenvalues) @ q.T


@pytest.mark.parametrize("velocity_filter", [FILTER, None], ids=["realistic", "perfect"])
def test_admitted_interval_agrees_with_the_eigenvalues_of_the_full_loop(velocity_filter):
    """Symmetric Kp with eigenvalues inside the interval (and Kv = kv I) give a 28 x 28 loop
    whose poles are inside the radius for every model error of the bound; one eigenvalue just
    outside puts a pole outside."""
    lo, hi = admitted_interval(KV, DT, velocity_filter, MODEL_ERROR, RADIUS)
    assert lo < 15000.0 < hi, f"admitted interval [{lo}, {hi}]: expected case 2's Kp = 15000 inside"
    rng = np.random.default_rng(23)
    kv = KV * np.eye(7)
    for _ in range(20):
        inside = np.exp(rng.uniform(np.log(lo * 1.001), np.log(min(hi, 2e5) / 1.001), size=7))
        radius = spectral_radius(_random_symmetric(rng, inside), kv, DT, velocity_filter, MODEL_ERROR)
        assert radius < RADIUS, f"spectral radius {radius}: expected < {RADIUS} for eigenvalues {inside}"
        below = inside.copy()
        below[rng.integers(7)] = lo * 0.9
        radius = spectral_radius(_random_symmetric(rng, below), kv, DT, velocity_filter, MODEL_ERROR)
        assert radius >= RADIUS, f"spectral radius {radius}: expected >= {RADIUS} with an eigenvalue below {lo}"


def test_loop_matrix_is_the_linear_error_dynamics():
    """The loop matrix steps the recursion written out by hand (velocity filter, hold, gamma)."""
    rng = np.random.default_rng(5)
    n, gamma = 3, 1.07
    kp, kv = rng.uniform(0, 2e4, (n, n)), rng.uniform(0, 600, (n, n))
    a = FILTER
    e, ed, e_prev, w_prev = (rng.normal(size=n) * 1e-4 for _ in range(4))
    x = np.concatenate([e, ed, e_prev, w_prev])
    A = loop_matrix(kp, kv, DT, a, gamma)
    for _ in range(50):
        w = a * w_prev + (1 - a) * (e - e_prev) / DT
        u = gamma * (kp @ e + kv @ w)
        e, ed, e_prev, w_prev = e + DT * ed - DT * DT / 2 * u, ed - DT * u, e, w
        x = A @ x
        np.testing.assert_allclose(x, np.concatenate([e, ed, e_prev, w_prev]), rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize("velocity_filter", [FILTER, None], ids=["realistic", "perfect"])
def test_damping_table_agrees_with_the_eigenvalues_of_the_full_loop(velocity_filter):
    """Each grid damping's interval: symmetric Kp with eigenvalues inside and Kv = kv_j I give a
    28 x 28 loop with every pole inside the radius (NumPy eigenvalues, every model error of the
    bound); one eigenvalue 1 % above the top puts a pole outside; the held damping's interval is
    :func:`admitted_interval`'s."""
    step, count = KV / 30, 31
    lo, hi = damping_table(step, count, DT, velocity_filter, MODEL_ERROR, RADIUS)
    assert math.isnan(lo[0]), f"lo[0] = {lo[0]}: expected no interval without damping"
    held = admitted_interval(KV, DT, velocity_filter, MODEL_ERROR, RADIUS)
    np.testing.assert_allclose([lo[-1], hi[-1]], held, rtol=1e-6, err_msg="the grid's top point vs admitted_interval")
    assert np.isfinite(lo).sum() >= 25, f"{np.isfinite(lo).sum()} grid dampings with an interval: expected >= 25"
    rng = np.random.default_rng(11)
    for j in (1, 2, 5, 15, 22, 30):
        if math.isnan(lo[j]):
            continue
        kv = j * step * np.eye(7)
        top = min(hi[j], 5e5)
        inside = np.exp(rng.uniform(np.log(lo[j] * 1.001), np.log(top / 1.001), size=7))
        radius = spectral_radius(_random_symmetric(rng, inside), kv, DT, velocity_filter, MODEL_ERROR)
        assert radius < RADIUS, f"kv = {j * step}: spectral radius {radius}, expected < {RADIUS} for {inside}"
        if hi[j] < 5e5:
            above = inside.copy()
            above[rng.integers(7)] = hi[j] * 1.01
            radius = spectral_radius(_random_symmetric(rng, above), kv, DT, velocity_filter, MODEL_ERROR)
            assert radius >= RADIUS, f"kv = {j * step}: spectral radius {radius}, expected >= {RADIUS} above {hi[j]}"


def test_admitted_pairs_decay_in_a_simulation_of_the_error_recursion():
    """The scalar error recursion written out by hand (hold, 100 Hz filter on differenced errors,
    model error across the bound, both holds), run 20,000 periods from a unit error with an admitted
    (lambda, kv) pair at each interval's edges: the decay per period over the last 10,000 periods
    is below the radius (within 1e-4, a double pole's polynomial factor); 5 % above the top it is
    not."""
    step, count = KV / 30, 31
    lo, hi = damping_table(step, count, DT, FILTER, MODEL_ERROR, RADIUS)

    def run(lam: float, kv: float, gamma: float, h: float, periods: int = 20000) -> float:
        """The decay per period over the last 10,000 periods (the largest pole's modulus, within
        the factor 2^(1/10000) a double pole's k r^k leaves); the state is rescaled every 100
        periods (its logarithm kept) so that nothing underflows."""
        e, ed, e_prev, w_prev = 1.0, 0.0, 1.0, 0.0
        log_size, logs = 0.0, []
        for k in range(periods):
            w = FILTER * w_prev + (1 - FILTER) * (e - e_prev) / DT
            u = gamma * (lam * e + kv * w)
            e, ed, e_prev, w_prev = e + DT * ed - h * u, ed - DT * u, e, w
            if k % 100 == 99:
                size = abs(e) + abs(e_prev) + DT * abs(ed) + DT * abs(w_prev)
                e, ed, e_prev, w_prev = e / size, ed / size, e_prev / size, w_prev / size
                log_size += math.log(size)
                if k in (periods - 10001, periods - 1):
                    logs.append(log_size)
        return math.exp((logs[1] - logs[0]) / 10000)

    cases = [(g, h) for g in (1 - MODEL_ERROR, 1.0, 1 + MODEL_ERROR) for h in (DT * DT / 2, 0.0)]
    for j in (3, 15, 30):
        for lam in (lo[j] * 1.0001, hi[j] * 0.9999):
            for gamma, h in cases:
                rate = run(lam, j * step, gamma, h)
                where = f"kv = {j * step}, lambda = {lam}, gamma = {gamma}, h = {h}"
                assert rate < RADIUS * (1 + 1e-4), f"{where}: decay {rate}, expected < {RADIUS}"
        slow = max(run(hi[j] * 1.05, j * step, gamma, h) for gamma, h in cases)
        assert slow > RADIUS * (1 + 1e-4), f"kv = {j * step}: decay {slow} 5 % above {hi[j]}, expected > {RADIUS}"


@pytest.fixture(scope="module", params=["fixed", "tuned"])
def safe_ga(robot, request):
    if not isinstance(robot.backend, CompiledBackend):
        pytest.skip("no C compiler: the safe variant runs in the compiled GA")
    ref = joint_reference(robot, 2, duration=0.1)
    scm = replace(
        case_study(2).controller("scm"), variant="safe", stability_radius=RADIUS, model_error=MODEL_ERROR,
        damping=request.param,
    )  # fmt: skip
    arrays = loop_arrays(robot, robot, ref, initial_state=(ref.q[0], ref.qd[0]))
    settings = LoopSettings(
        dt=ref.dt, integrator="euler", substeps=1, cutting=False, cutting_force=0.0, cutting_speed=0.0,
        threshold=0.0, limit_tolerance=0.05, sensing=True, velocity_filter=FILTER,
    )  # fmt: skip
    return scm, compiled_ga(scm, ClosedLoopDriver(robot.backend), robot, arrays, ref.dt, settings), ref


def _damping_of(scm, kv_genes):
    """The damping and interval ga.c gives a candidate (grid point nearest to the mean diagonal)."""
    table = scm.damping_table(DT, FILTER)
    if table is None:
        return KV, scm.admitted_interval(DT, FILTER)
    step, lo, hi = table
    j = min(max(int(np.floor(np.mean(np.diag(kv_genes)) / step + 0.5)), 0), len(lo) - 1)
    return j * step, (lo[j], hi[j])


def test_compiled_ga_never_admits_an_unstable_candidate(safe_ga):
    """Seeded samples around the fixed gains and across the GA's box: every candidate the
    compiled GA admits (a cost below the penalty) closes a loop with every pole inside the radius
    (NumPy's eigenvalues of the full loop, repaired gains: the damping of its grid point); every
    rejected one has an eigenvalue of its symmetrised Kp outside its admitted interval."""
    scm, ga, ref = safe_ga
    rng = np.random.default_rng(0)
    lower, upper = scm.bounds()
    fixed = np.concatenate([scm.fixed.Kp.ravel(), scm.fixed.Kv.ravel()])
    spread = rng.uniform(0.0, 0.6, size=(120, 1)) * (upper - lower)
    genes = np.clip(fixed + rng.normal(size=(120, len(fixed))) * spread, lower, upper)
    genes = np.vstack([genes, rng.uniform(lower, upper, size=(40, len(fixed)))])
    cost = ga.predict(0, ref.q[0], ref.qd[0], genes)
    admitted = cost < 1.0
    assert 10 < admitted.sum() < len(genes), f"admitted {admitted.sum()} of {len(genes)}: expected a mix"
    for g, ok in zip(genes, admitted, strict=True):
        kp, kv_genes = scm.split(g)
        kv, (lo, hi) = _damping_of(scm, kv_genes)
        sym = (kp + kp.T) / 2
        eig = np.linalg.eigvalsh(sym)
        if ok:
            radius = spectral_radius(sym, kv * np.eye(7), DT, FILTER, MODEL_ERROR)
            assert radius < RADIUS, f"admitted candidate (kv {kv}) with spectral radius {radius}: expected < {RADIUS}"
        else:
            assert not lo < hi or eig[0] < lo * (1 + 1e-6) or eig[-1] > hi * (1 - 1e-6), (
                f"rejected candidate with Kp eigenvalues [{eig[0]}, {eig[-1]}]: expected one outside [{lo}, {hi}]"
            )


def test_safe_variant_is_checked_at_the_boundary():
    scm = case_study(2).controller("scm", variant="paper")
    with pytest.raises(InputError, match="variant = 'risky'"):
        replace(scm, variant="risky")
    with pytest.raises(InputError, match="stability_radius = 1.0"):
        replace(scm, variant="safe", stability_radius=1.0)
    with pytest.raises(InputError, match="fixed Kv"):
        SwitchingControl.with_gains(15000.0, [600.0, 500, 600, 600, 600, 600, 600], variant="safe",
                                    kp_bounds=(0.0, 15000.0), kv_bounds=(0.0, 600.0))  # fmt: skip
    assert SwitchingControl.with_gains(5000.0, 300.0).variant == "safe"  # the library's default too
    with pytest.raises(InputError, match="damping = 'soft'"):
        replace(scm, variant="safe", damping="soft")
    with pytest.raises(InputError, match="stiffness_box = 6: the fixed gains are not exactly representable"):
        replace(scm, variant="safe", stiffness_box=6)
    assert replace(scm, variant="safe").bounds()[1][0] == 5 * 15000.0


def _case2(robot, variant, seed, duration, **options):
    ref = joint_reference(robot, 2, duration=duration)
    return run_case(
        robot, 2, controller="scm", external_force=True, seed=seed, reference=ref, scm_variant=variant, **options
    )


def test_safe_runs_are_reproducible_per_seed(robot):
    if not isinstance(robot.backend, CompiledBackend):
        pytest.skip("no C compiler")
    runs = [_case2(robot, "safe", seed, 0.3, encoder_resolution=1e-6) for seed in (3, 3, 4)]
    assert len(runs[0].activations) > 0
    for name in ("q", "qd", "effort", "mode"):
        a, b, c = (getattr(r, name) for r in runs)
        assert np.array_equal(a, b, equal_nan=name != "mode"), f"{name}: expected the same run for seed 3"
    assert not np.array_equal(runs[0].effort, runs[2].effort), "seed 4 gave seed 3's efforts: expected another run"
    assert runs[0].summary()["scm_variant"] == "safe"


def test_realistic_sensing_paper_diverges_safe_holds(robot):
    """Case 2 with the tool force, 1 um encoders, a model 10 % heavy, seed 0: the paper's variant
    diverges at 2.225 s; the safe one holds over the same 2.3 s with its error below CFC's."""
    if not isinstance(robot.backend, CompiledBackend):
        pytest.skip("no C compiler")
    options = dict(encoder_resolution=1e-6, controller_model=robot.parameters.scaled(mass=1.1))
    with pytest.raises(SimulationError, match="diverged"):
        _case2(robot, "paper", 0, 2.3, **options)
    safe = _case2(robot, "safe", 0, 2.3, **options)
    assert safe.success
    assert safe.summary()["max_tip_error_m"] < 0.82e-3


def _held_pattern(run, hold, seen=None, watch_from=None):
    """Check the hold in a run's modes: an admitted set (not dropped for the fixed gains) controls
    exactly ``hold`` samples from its activation, with no activation in between, unless the drop
    rule (:func:`dropped_at` on the recorded ``seen`` errors, from period ``watch_from``) says where
    it was dropped: it then controls the samples before that one only; a set not admitted controls
    its sample only. Returns the counts of admitted activations and of held sets dropped."""
    n = len(run.mode)
    samples = [a.sample for a in run.activations]
    admitted = drops = 0
    spans = []
    for i, a in enumerate(run.activations):
        dropped = a.best_fitness == a.fixed_gains_fitness
        span = 1 if dropped else min(hold, n - a.sample)
        if not dropped and seen is not None:
            at = dropped_at(seen, a.sample, hold, watch_from)
            if at is not None:
                span, drops = at - a.sample, drops + 1
                assert seen[at] > seen[a.sample], f"set from {a.sample} dropped at {at}: the error did not rise"
        spans.append(span)
        admitted += not dropped
        held = run.mode[a.sample : a.sample + span]
        assert (held == 1).all(), f"activation at {a.sample}: expected {span} GA samples"
        if i + 1 < len(samples):
            assert samples[i + 1] >= a.sample + span, f"activation at {samples[i + 1]} inside the hold from {a.sample}"
        end = a.sample + span
        if end < n and (i + 1 == len(samples) or samples[i + 1] != end):
            assert run.mode[end] == 0, f"sample {end} after the hold from {a.sample}: expected the fixed gains"
    assert np.count_nonzero(run.mode == 1) == sum(spans)
    return admitted, drops


def _run_with_seen(robot, ref, scm, **options):
    """A run and the error its controller saw at each sample where the threshold was tested (the
    compiled loop's record, ``LoopArrays.seen``), from the simulator's own steps."""
    run = prepare(robot, ref, scm, Scenario.of(None, options))
    outcome = drive(run)
    result = run.result(outcome, None)
    assert result.success, result.message
    return result, run.job.arrays.seen.copy(), outcome


@pytest.mark.parametrize("hold", [1, 7, 20])
def test_an_admitted_gain_set_is_held_for_exactly_its_hold(robot, monkeypatch, hold):
    """Case 2 with the tool force and 1 um encoders, 0.3 s: every admitted set controls exactly
    `hold` samples (no GA in between), a dropped one its sample only; the GA inside the compiled
    loop (the hold in csrc/ga.c) and called per activation from Python (the hold in engines.py)
    give the same run to the last bit; the same seed gives the same run."""
    if not isinstance(robot.backend, CompiledBackend):
        pytest.skip("no C compiler")
    from vgtarm.simulation import engines

    ref = joint_reference(robot, 2, duration=0.3)
    scm = replace(case_study(2).controller("scm", variant="safe"), hold=hold, watch_from=None)
    assert scm.hold_periods == hold and scm.measured_switching
    runs = []
    for in_loop in (True, False, True):
        monkeypatch.setattr(engines, "GA_IN_LOOP", in_loop)
        force = case_study(2).external_force
        runs.append(simulate(robot, ref, scm, external_force=force, seed=2, encoder_resolution=1e-6))
    inside = runs[0]
    assert inside.success and len(inside.activations) > 2
    admitted, _ = _held_pattern(inside, hold)
    assert admitted > 0, "expected admitted gain sets"
    assert inside.summary()["scm_hold_drops"] == 0
    for other in runs[1:]:
        for name in ("q", "qd", "effort", "tip_error", "mode"):
            np.testing.assert_array_equal(getattr(other, name), getattr(inside, name), err_msg=name)
        assert [a.sample for a in other.activations] == [a.sample for a in inside.activations]


def test_the_hold_survives_pauses_and_chunks(robot):
    """A run in chunks with progress (and the loop's pauses) holds across the chunk boundaries: the
    same run as in one call."""
    if not isinstance(robot.backend, CompiledBackend):
        pytest.skip("no C compiler")
    ref = joint_reference(robot, 2, duration=0.3)
    scm = case_study(2).controller("scm", variant="safe")
    options = dict(external_force=case_study(2).external_force, seed=5, encoder_resolution=1e-6)
    whole = simulate(robot, ref, scm, **options)
    chunked = simulate(robot, ref, scm, progress=lambda k, n: None, **options)
    assert whole.summary()["scm_hold_drops"] > 0  # the drop rule crosses chunks and pauses too
    for name in ("q", "effort", "mode"):
        np.testing.assert_array_equal(getattr(chunked, name), getattr(whole, name), err_msg=name)
    assert chunked.summary()["scm_hold_drops"] == whole.summary()["scm_hold_drops"]


def test_dropped_at_is_the_drop_rule():
    """The rule written out, on hand-made errors: the first period from ``watch_from`` whose error
    exceeds the one at the activation (equal is kept), never at or past the hold."""
    seen = np.array([0.0, 3.0, 9.0, 2.0, 3.0, 3.5, 1.0])
    assert dropped_at(seen, 1, 6, 2) == 5  # period 1 (9.0) is not watched; 3.0 is not above 3.0
    assert dropped_at(seen, 1, 6, 1) == 2
    assert dropped_at(seen, 1, 4, 2) is None  # 3.5 comes at period 4, after the hold of 4
    assert dropped_at(seen, 3, 10, 1) == 4  # the end of the recorded errors: kept until then
    assert dropped_at(seen, 6, 10, 1) is None


@pytest.mark.parametrize("hold", [10, 20])
def test_a_held_set_whose_error_rises_is_dropped_within_one_period(robot, monkeypatch, hold):
    """Case 2 with the tool force and 1 um encoders, 0.4 s: every held set whose seen error (the
    controller model's tip at the encoder readings) rises above its value at the set's activation,
    from period 2 on, runs the fixed gains at that very period, and a set whose error never does
    is held its whole hold (:func:`dropped_at` applied to the recorded errors: the rule written
    out, apart from both loops); the GA inside the compiled loop (csrc/ga.c) and called per
    activation from Python (engines.py) make the same run to the last bit."""
    if not isinstance(robot.backend, CompiledBackend):
        pytest.skip("no C compiler")
    from vgtarm.simulation import engines

    ref = joint_reference(robot, 2, duration=0.4)
    scm = replace(case_study(2).controller("scm", variant="safe"), hold=hold)
    assert scm.watch_from == 2
    options = dict(external_force=case_study(2).external_force, seed=2, encoder_resolution=1e-6)
    runs = []
    for in_loop in (True, False):
        monkeypatch.setattr(engines, "GA_IN_LOOP", in_loop)
        runs.append(_run_with_seen(robot, ref, scm, **options))
    (inside, seen, outcome), (other, seen_other, outcome_other) = runs
    admitted, drops = _held_pattern(inside, hold, seen, scm.watch_from)
    assert drops > 0 and admitted > drops, f"expected sets dropped and sets held: {drops} of {admitted}"
    assert len(outcome.drops) == drops == inside.summary()["scm_hold_drops"]
    assert outcome.drops == outcome_other.drops
    # the error the loop recorded is the one the controller saw (computed apart, in NumPy)
    measured = inside.tip_error_measured
    written = ~np.isnan(seen)
    np.testing.assert_allclose(seen[written], measured[written], rtol=1e-9, atol=1e-12)
    for name in ("q", "qd", "effort", "tip_error", "mode"):
        np.testing.assert_array_equal(getattr(other, name), getattr(inside, name), err_msg=name)
    np.testing.assert_array_equal(seen_other, seen)


def test_the_safe_variant_switches_on_the_measured_tip_error(robot):
    """With 1 um encoders the GA runs exactly where the tip error the controller saw exceeds the
    threshold (every fixed-gain sample at or below it, every activation above); with
    ``switch_on="true"`` the same holds for the true error; the paper's variant keeps the true
    error and no hold."""
    if not isinstance(robot.backend, CompiledBackend):
        pytest.skip("no C compiler")
    ref = joint_reference(robot, 2, duration=0.5)
    safe = case_study(2).controller("scm", variant="safe")
    options = dict(external_force=case_study(2).external_force, seed=1, encoder_resolution=1e-6)
    for switch_on in ("measured", "true"):
        # no drop rule here: a dropped set's sample runs the fixed gains above the threshold
        run = simulate(robot, ref, replace(safe, switch_on=switch_on, watch_from=None), **options)
        seen = run.tip_error_measured if switch_on == "measured" else run.tip_error
        assert seen is not None and len(run.activations) > 3
        activations = [a.sample for a in run.activations]
        assert seen[run.mode == 0].max() <= safe.threshold < seen[activations].min(), switch_on
    paper = case_study(2).controller("scm", variant="paper")
    assert (paper.hold_periods, paper.measured_switching) == (1, False)


def test_hold_and_switch_on_are_checked_at_the_boundary():
    scm = case_study(2).controller("scm", variant="paper")
    safe = replace(scm, variant="safe")
    assert (safe.hold_periods, safe.horizon) == (10, 20)
    assert replace(safe, horizon=1).hold_periods == 1
    for bad in (0, 21, 2.5, True):
        with pytest.raises(InputError, match="hold = "):
            replace(safe, hold=bad)
    for bad in (0, 2.0, "2", False):
        with pytest.raises(InputError, match="watch_from = "):
            replace(safe, watch_from=bad)
    assert (replace(safe, hold=5, watch_from=9).watch_period, replace(safe, watch_from=None).watch_period) == (5, 10)
    with pytest.raises(InputError, match="switch_on = 'estimated'"):
        replace(safe, switch_on="estimated")
    with pytest.raises(InputError, match="the paper's variant holds"):
        replace(scm, hold=5)
    with pytest.raises(InputError, match="the paper's variant holds"):
        replace(scm, switch_on="measured")
    assert replace(scm, hold=1, switch_on="true").hold_periods == 1


def test_the_damping_table_is_kept_in_the_cache_folder(tmp_path, monkeypatch):
    """A new process reads the table from the cache folder: the same numbers as computed; a
    damaged file is recomputed and replaced."""
    from vgtarm.control import safety

    monkeypatch.setenv("VGTARM_CACHE_DIR", str(tmp_path))
    args = (60.0, 3, DT, FILTER, MODEL_ERROR, RADIUS)
    computed = safety._damping_table(*args)
    first = safety.damping_table.__wrapped__(*args)
    (stored,) = tmp_path.glob("safety-table-*.json")
    np.testing.assert_array_equal(np.array(first), np.array(computed))
    monkeypatch.setattr(safety, "_damping_table", lambda *a: pytest.fail("recomputed a stored table"))
    np.testing.assert_array_equal(np.array(safety.damping_table.__wrapped__(*args)), np.array(computed))
    stored.write_text("{not json", encoding="utf-8")
    monkeypatch.undo()
    monkeypatch.setenv("VGTARM_CACHE_DIR", str(tmp_path))
    np.testing.assert_array_equal(np.array(safety.damping_table.__wrapped__(*args)), np.array(computed))
    assert np.array_equal(np.array(safety.damping_table.__wrapped__(*args)), np.array(computed), equal_nan=True)


def test_the_library_default_is_the_safe_variant():
    """Users get the safe variant from the Python API as from the command line and the studies;
    the paper's is there by name."""
    import inspect

    from vgtarm.experiment.cases import run_path

    assert SwitchingControl.with_gains(5000.0, 300.0).variant == "safe"
    assert case_study(2).controller("scm").variant == "safe"
    assert case_study(2).controller("scm", variant="paper").variant == "paper"
    for function in (run_case, run_path):
        assert inspect.signature(function).parameters["scm_variant"].default == "safe", function.__name__
    with pytest.raises(InputError, match="hold: options of the switching method, not of cfc"):
        case_study(2).controller("cfc", hold=5)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--scm-hold", "5"], "--scm-hold 5: options of the switching method; expected --controller scm"),
        (["--controller", "scm", "--scm-variant", "paper", "--scm-switch-on", "true"], "expected --scm-variant safe"),
        (
            ["--controller", "scm", "--scm-hold", "21"],
            r"--scm-hold 21: expected at most the GA's horizon \(--horizon 20\)",
        ),
        (["--controller", "scm", "--horizon", "4", "--scm-hold", "5"], r"\(--horizon 4\)"),
        (
            ["--controller", "scm", "--scm-hold", "0"],
            r"argument --scm-hold: expected a whole number of control periods from 1 to the horizon .*, got 0$",
        ),
        (["--controller", "scm", "--scm-hold", "x"], "argument --scm-hold"),
        (["--controller", "scm", "--scm-switch-on", "estimated"], "argument --scm-switch-on: invalid choice"),
    ],
)
def test_the_scm_options_of_simulate_are_checked(capsys, tmp_path, argv, message):
    import re

    from vgtarm.app.cli.command import main

    out = tmp_path / "run"
    try:
        status = main(["simulate", "--case", "2", "--duration", "0.01", "-q", "--out", str(out), *argv])
    except SystemExit as exit_:  # argparse's own refusal
        status = exit_.code
    err = capsys.readouterr().err
    assert status != 0 and re.search(message, err), err
    assert not out.exists(), "a refused run left a folder"


def test_the_scm_options_of_simulate_are_stored_in_the_summary(capsys, tmp_path, robot):
    """--scm-hold and --scm-switch-on reach the controller and the summary (so the run can be
    repeated), with the drop rule's period and count."""
    import json

    from vgtarm.app.cli.command import main

    if not isinstance(robot.backend, CompiledBackend):
        pytest.skip("no C compiler")
    out = tmp_path / "run"
    argv = ["simulate", "--case", "2", "--duration", "0.1", "--external-force", "--controller", "scm", "-q"]
    assert main([*argv, "--scm-hold", "5", "--scm-switch-on", "true", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert (summary["scm_variant"], summary["scm_hold"], summary["scm_switch_on"]) == ("safe", 5, "true")
    assert summary["scm_watch_from"] == 2 and isinstance(summary["scm_hold_drops"], int)
    assert summary["ga_activations"] > 0
    capsys.readouterr()


def test_studies_pass_the_scm_options_to_the_safe_variant_only():
    """``scm_hold`` and ``scm_switch_on`` are study parameters: checked, given to the safe points'
    controller (a sweep over the variant runs the paper's points without them), repeated by the
    points' ``vgtarm simulate`` command, and left out of the ids at their defaults."""
    from vgtarm.app.study_points import experiment_of, simulate_command
    from vgtarm.errors import ConfigError
    from vgtarm.study import parse_study
    from vgtarm.study.spec import point_id_of

    data = {
        "study": {"name": "t", "case": 2, "duration": 0.01, "seeds": 1},
        "grid": {"controller": "scm", "scm_variant": ["safe", "paper"], "scm_hold": 4, "scm_switch_on": "true"},
    }
    safe, paper = sorted(parse_study(data).points(), key=lambda p: p.inputs["scm_variant"] != "safe")
    controller = experiment_of(safe.inputs, {}).controller(7)
    assert (controller.hold_periods, controller.measured_switching) == (4, False)
    assert experiment_of(paper.inputs, {}).controller(7).hold_periods == 1
    command = simulate_command(safe.inputs)
    assert command[command.index("--scm-hold") + 1] == "4" and "--scm-switch-on" in command
    assert "--scm-hold" not in simulate_command(paper.inputs)
    for key, bad in (("scm_hold", 0), ("scm_hold", 2.5), ("scm_switch_on", "estimated")):
        with pytest.raises(ConfigError, match=f"{key} = "):
            parse_study({**data, "grid": {**data["grid"], key: bad}})
    plain = {k: v for k, v in paper.inputs.items() if k not in ("scm_hold", "scm_switch_on")}
    defaults = {**plain, "scm_hold": None, "scm_switch_on": None}
    assert point_id_of(defaults, {}) == point_id_of(plain, {}) != point_id_of(paper.inputs, {})


def test_the_drop_rule_resumes_exactly_after_pauses_inside_samples(robot, monkeypatch):
    """The compiled loop paused inside (nearly) every sample (RK4 with three sub-steps, a budget of
    one or two units a call), dropped samples included: the same run and drops as in one call."""
    if not isinstance(robot.backend, CompiledBackend):
        pytest.skip("no C compiler")
    from functools import partial

    from vgtarm.simulation import engines

    ref = joint_reference(robot, 2, duration=0.4)
    scm = replace(case_study(2).controller("scm", variant="safe"), hold=10)
    options = dict(
        external_force=case_study(2).external_force, seed=2, encoder_resolution=1e-6, integrator="rk4", substeps=3
    )
    runs = []
    for budget in (None, 2, 1):
        monkeypatch.setattr(engines, "ClosedLoopDriver", partial(ClosedLoopDriver, slice_budget=budget))
        runs.append(_run_with_seen(robot, ref, scm, **options))
    (whole, _, outcome) = runs[0]
    assert len(outcome.drops) > 0
    for result, _, sliced in runs[1:]:
        assert sliced.drops == outcome.drops
        for name in ("q", "qd", "effort", "tip_error", "mode"):
            np.testing.assert_array_equal(getattr(result, name), getattr(whole, name), err_msg=name)
