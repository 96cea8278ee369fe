"""Closed-loop simulation: computed force control identities, the switching rule, reproducibility,
divergence handling, and the compiled loop against its NumPy twin."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.linalg import expm

import vgtarm
from vgtarm.control import ComputedForceControl, SwitchingControl
from vgtarm.ga import GAOptions
from vgtarm.model.compiled import InterpretedBackend, build_functions
from vgtarm.simulation import ExternalForce, JointReference, simulate
from vgtarm.simulation.result import MODE_FIXED, MODE_GA, MODE_NOT_RUN

from .conftest import assert_close

AMPLITUDE = np.array([0.02, 0.015, 0.02, 0.01, 0.02, 0.015, 0.5])
OMEGA = np.array([1.0, 1.3, 0.7, 1.1, 0.9, 1.2, 2.0])


def smooth_reference(robot, duration=0.5, dt=1e-3, amplitude=AMPLITUDE) -> JointReference:
    """A joint reference with exact rates: ``q_d = home + A sin(w t)``."""
    t = np.arange(0.0, duration + 1e-9, dt)
    wt = OMEGA * t[:, None]
    return JointReference(
        t,
        robot.parameters.home + amplitude * np.sin(wt),
        amplitude * OMEGA * np.cos(wt),
        -amplitude * OMEGA**2 * np.sin(wt),
    )


CFC = ComputedForceControl.with_gains(5000.0, 300.0)


def test_cfc_with_exact_model_tracks_to_integrator_accuracy(robot):
    ref = smooth_reference(robot, duration=1.0)
    start = (ref.q[0], ref.qd[0])
    euler = simulate(robot, ref, CFC, initial_state=start)
    rk4 = simulate(robot, ref, CFC, initial_state=start, integrator="rk4", substeps=4)
    assert euler.summary()["max_tip_error_m"] < 5e-6  # micrometres
    assert rk4.summary()["max_tip_error_m"] < 1e-6
    fine = simulate(robot, smooth_reference(robot, duration=1.0, dt=5e-4), CFC, initial_state=start)
    # The error comes from sampling the control: halving the period halves it.
    ratio = euler.summary()["max_tip_error_m"] / fine.summary()["max_tip_error_m"]
    assert 1.6 < ratio < 2.5


def test_joint_error_follows_the_euler_discretised_linear_error_equation(robot):
    """With an exact model and explicit Euler, ``e`` obeys exactly the Euler recursion of
    ``e'' + Kv e' + Kp e = 0`` plus the reference's own sampling residuals."""
    ref = smooth_reference(robot, duration=0.3)
    rng = np.random.default_rng(30)
    q0 = ref.q[0] + rng.normal(scale=2e-3, size=7)
    qd0 = ref.qd[0] + rng.normal(scale=2e-2, size=7)
    gains = ComputedForceControl.with_gains(np.diag(rng.uniform(2000, 6000, 7)), np.diag(rng.uniform(100, 300, 7)))
    run = simulate(robot, ref, gains, initial_state=(q0, qd0))
    Kp, Kv, dt = gains.gains.Kp, gains.gains.Kv, ref.dt
    e, e_dot = ref.q[0] - q0, ref.qd[0] - qd0
    for k in range(len(ref.t) - 1):
        rho = ref.q[k + 1] - ref.q[k] - dt * ref.qd[k]
        sigma = ref.qd[k + 1] - ref.qd[k] - dt * ref.qdd[k]
        e, e_dot = e + dt * e_dot + rho, e_dot - dt * (Kp @ e + Kv @ e_dot) + sigma
        assert_close(ref.q[k + 1] - run.q[k + 1], e, rtol=1e-6, atol=1e-12)
        assert_close(ref.qd[k + 1] - run.qd[k + 1], e_dot, rtol=1e-6, atol=1e-10)


def test_joint_error_approaches_the_continuous_linear_solution(robot):
    """From a perturbed start with a resting reference, the error tends to ``expm(A t) e0``."""
    ref = smooth_reference(robot, duration=0.2, amplitude=np.zeros(7))
    rng = np.random.default_rng(31)
    e0 = rng.normal(scale=2e-3, size=7)
    Kp, Kv = 5000.0 * np.eye(7), 300.0 * np.eye(7)
    A = np.block([[np.zeros((7, 7)), np.eye(7)], [-Kp, -Kv]])
    worst = []
    for dt in (1e-3, 5e-4):
        r = smooth_reference(robot, duration=0.2, dt=dt, amplitude=np.zeros(7))
        run = simulate(robot, r, CFC, initial_state=(r.q[0] - e0, np.zeros(7)), integrator="rk4", substeps=4)
        exact = np.array([(expm(A * t) @ np.concatenate([e0, np.zeros(7)]))[:7] for t in r.t])
        worst.append(np.abs(r.q - run.q - exact).max() / np.abs(e0).max())
    assert worst[1] < 0.05
    assert 1.6 < worst[0] / worst[1] < 2.5  # first order in the control period (zero-order hold)
    assert ref.q.shape == (201, 7)


@pytest.mark.parametrize("integrator", ["euler", "semi_implicit_euler", "rk4"])
def test_compiled_loop_matches_its_numpy_twin(robot, integrator):
    slow = vgtarm.Robot(robot.parameters, InterpretedBackend(build_functions()))
    ref = smooth_reference(robot, duration=0.06)
    kwargs = dict(
        external_force=ExternalForce(),
        integrator=integrator,
        substeps=2,
        seed=3,
        controller_model=robot.parameters.scaled(mass=1.1, friction=0.9),
    )
    fast = simulate(robot, ref, CFC, **kwargs)
    twin = simulate(slow, ref, CFC, **kwargs)
    assert twin.metadata["backend"] == "interpreted"
    for name in ("q", "qd", "effort", "f_ext", "tip", "tip_error"):
        assert_close(getattr(fast, name), getattr(twin, name), rtol=1e-9, atol=1e-12, what=name)


def test_same_seed_same_numbers_bit_for_bit(robot):
    ref = smooth_reference(robot, duration=0.3)
    scm = SwitchingControl.with_gains(5000.0, 300.0, variant="paper", threshold=5e-5, ga=GAOptions(max_generations=8))
    runs = [simulate(robot, ref, scm, external_force=ExternalForce(), seed=seed) for seed in (7, 7, 8)]
    for name in ("q", "qd", "effort", "f_ext", "tip_error"):
        np.testing.assert_array_equal(getattr(runs[0], name), getattr(runs[1], name))
    assert runs[0].activations and [a.best_fitness for a in runs[0].activations] == [
        a.best_fitness for a in runs[1].activations
    ]
    assert not np.array_equal(runs[0].f_ext, runs[2].f_ext)


def test_switching_happens_when_and_only_when_the_error_exceeds_the_threshold(robot):
    ref = smooth_reference(robot, duration=0.3)
    threshold = 5e-5
    scm = SwitchingControl.with_gains(
        5000.0, 300.0, variant="paper", threshold=threshold, ga=GAOptions(max_generations=10)
    )
    run = simulate(robot, ref, scm)
    assert run.activations
    above = run.tip_error > threshold
    np.testing.assert_array_equal(run.mode == MODE_GA, above)
    np.testing.assert_array_equal(run.mode == MODE_FIXED, ~above)
    assert [a.sample for a in run.activations] == list(np.flatnonzero(above))
    # Seeded with the fixed gains and elitist, the GA is never predicted worse than them.
    assert all(a.best_fitness <= a.fixed_gains_fitness for a in run.activations)


def test_fitness_prediction_horizon_decides_whether_gains_matter(robot):
    ref = smooth_reference(robot, duration=0.3)
    one_step = SwitchingControl.with_gains(
        5000.0, 300.0, variant="paper", threshold=5e-5, horizon=1, ga=GAOptions(max_generations=5)
    )
    run = simulate(robot, ref, one_step)
    # A one-step Euler prediction does not depend on the gains: the GA cannot improve on them
    # and the run is that of computed force control.
    assert all(a.best_fitness == a.fixed_gains_fitness for a in run.activations)
    np.testing.assert_array_equal(run.q, simulate(robot, ref, CFC).q)
    longer = SwitchingControl.with_gains(
        5000.0, 300.0, variant="paper", threshold=5e-5, horizon=20, ga=GAOptions(max_generations=20)
    )
    assert any(a.best_fitness < a.fixed_gains_fitness for a in simulate(robot, ref, longer).activations)


def test_compiled_fitness_matches_numpy_and_a_full_model_prediction(robot):
    from vgtarm.control import predict_tip_error
    from vgtarm.model.closedloop import ClosedLoopDriver

    ref = smooth_reference(robot, duration=0.05)
    H = 15
    rng = np.random.default_rng(32)
    Kp = rng.uniform(0, 5000, size=(6, 7, 7))
    Kv = rng.uniform(0, 300, size=(6, 7, 7))
    q0 = ref.q[0] + rng.normal(scale=1e-3, size=7)
    qd0 = ref.qd[0] + rng.normal(scale=1e-2, size=7)
    window = slice(0, H + 1)
    tip_d = robot.tip_position(ref.q[window])
    args = (robot.parameter_vector, ref.dt, q0, qd0, ref.q[window], ref.qd[window], ref.qdd[window], tip_d)
    compiled = ClosedLoopDriver(robot.backend).ga_predictor(*args)(Kp, Kv)
    numpy_version = predict_tip_error(robot, *args[1:], Kp, Kv)
    assert_close(compiled, numpy_version, rtol=1e-12, atol=1e-15)
    # The same prediction through the controller's full model (M^, C^ and forward dynamics).
    cfc = ComputedForceControl.with_gains(5000, 300)
    for c in range(2):
        q, qd, total = q0.copy(), qd0.copy(), 0.0
        gains = vgtarm.control.Gains.of(Kp[c], Kv[c])
        for j in range(H):
            F = cfc.effort(robot, q, qd, ref.q[j], ref.qd[j], ref.qdd[j], gains=gains)
            qdd = robot.forward_dynamics(q, qd, F)
            q, qd = q + ref.dt * qd, qd + ref.dt * qdd
            total += float(np.sum((tip_d[j + 1] - robot.tip_position(q)) ** 2))
        assert compiled[c] == pytest.approx(np.sqrt(total), rel=1e-8)


def test_external_force_opposes_motion_and_raises_the_error(robot):
    ref = smooth_reference(robot, duration=0.5)
    start = (ref.q[0], ref.qd[0])
    free = simulate(robot, ref, CFC, initial_state=start)
    cutting = simulate(robot, ref, CFC, initial_state=start, external_force=ExternalForce(disturbance=False))
    velocity, _ = robot.tip_velocity(cutting.q, cutting.qd)
    moving = np.linalg.norm(velocity, axis=1) > 1e-3
    assert (np.einsum("ij,ij->i", cutting.f_ext[moving], velocity[moving]) < 0).all()
    assert_close(np.linalg.norm(cutting.f_ext[moving], axis=1), np.full(moving.sum(), 20.0), rtol=1e-12)
    assert cutting.summary()["max_tip_error_m"] > 10 * free.summary()["max_tip_error_m"]
    disturbed = simulate(robot, ref, CFC, initial_state=start, external_force=ExternalForce(cutting=False), seed=1)
    assert np.abs(disturbed.f_ext).max() <= 5.0
    assert np.abs(disturbed.f_ext).max() > 4.5


def test_a_wrong_controller_model_is_used_and_costs_accuracy(robot):
    ref = smooth_reference(robot, duration=0.5)
    start = (ref.q[0], ref.qd[0])
    exact = simulate(robot, ref, CFC, initial_state=start)
    wrong = simulate(robot, ref, CFC, initial_state=start, controller_model=robot.parameters.scaled(mass=1.3))
    assert wrong.summary()["max_tip_error_m"] > 5 * exact.summary()["max_tip_error_m"]
    assert "mass x1.3" in wrong.metadata["controller_model"]


def test_divergence_stops_with_when_and_why_and_keeps_the_samples(robot):
    ref = smooth_reference(robot, duration=1.0)
    weightless = robot.parameters.scaled(mass=1e-3, inertia=1e-3, friction=1e-3)
    limp = ComputedForceControl.with_gains(0.0, 0.0)
    with pytest.raises(vgtarm.SimulationError, match=r"diverged at t = \d+\.\d+ s \(sample \d+ of 1001\)") as info:
        simulate(robot, ref, limp, controller_model=weightless)
    result = info.value.result
    assert not result.success
    reached = result.mode != MODE_NOT_RUN
    assert 0 < reached.sum() < len(ref.t)
    assert np.isfinite(result.q[reached]).all() and np.isnan(result.q[~reached]).all()


def test_a_diverging_run_ends_as_a_divergence_in_the_numpy_loop_too(robot):
    """Absurd gains drive the NumPy twin's measured state beyond what the model accepts: the run
    ends as a divergence with its samples (SimulationError), as the compiled loop's does, not as a
    bad-argument error of a model call inside the loop."""
    slow = vgtarm.Robot(robot.parameters, InterpretedBackend(build_functions()))
    ref = smooth_reference(robot, duration=0.05)
    wild = ComputedForceControl.with_gains(1e12, 1e12)
    for plant in (robot, slow):
        with pytest.raises(vgtarm.SimulationError, match=r"diverged at t = ") as info:
            simulate(plant, ref, wild, velocity_noise=0.5, seed=1)
        assert not info.value.result.success and info.value.result.mode[0] != MODE_NOT_RUN


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"integrator": "leapfrog"}, "integrator = 'leapfrog': expected one of"),
        ({"substeps": 0}, "substeps"),
        ({"seed": -1}, "seed"),
    ],
)
def test_bad_simulation_arguments_are_named(robot, kwargs, message):
    with pytest.raises(vgtarm.InputError, match=message):
        simulate(robot, smooth_reference(robot, duration=0.01), CFC, **kwargs)


def test_results_are_saved_atomically_with_the_summary_keys(robot, tmp_path):
    ref = smooth_reference(robot, duration=0.1)
    scm = SwitchingControl.with_gains(5000.0, 300.0, variant="paper", threshold=5e-5, ga=GAOptions(max_generations=3))
    run = simulate(robot, ref, scm, metadata={"case": "smooth"})
    out = run.save(tmp_path / "run")
    summary = json.loads((out / "summary.json").read_text())
    for key in (
        "case",
        "controller",
        "external_force",
        "seed",
        "dt_s",
        "simulated_time_s",
        "wall_time_s",
        "max_tip_error_m",
        "rms_tip_error_m",
        "max_tip_error_after_transient_m",
        "peak_force_n",
        "ga_activations",
        "ga_time_s",
        "reference_rates",
    ):
        assert key in summary, key
    assert summary["ga_activations"] == len(run.activations) > 0
    header = (out / "timeseries.csv").read_text().splitlines()[0].split(",")
    assert header[:8] == ["t", "x_d", "y_d", "z_d", "x", "y", "z", "tip_error"]
    table = np.loadtxt(out / "timeseries.csv", delimiter=",", skiprows=1)
    assert table.shape == (len(ref.t), len(header))
    names = ["ga_activations.csv", "summary.json", "timeseries.csv"]
    assert sorted(p.name for p in out.iterdir()) == [".vgtarm-output", *names]  # the list of what it holds


def test_a_run_holds_blas_to_one_thread_and_gives_it_back() -> None:
    """The run's wrapper limits every loaded BLAS to one thread while it runs, and restores the limit
    after, with the libraries looked up once per process."""
    from threadpoolctl import threadpool_info, threadpool_limits

    from vgtarm.machine import _thread_pools
    from vgtarm.simulation.simulator import _blas_on_one_thread

    def blas_threads() -> list[int]:
        return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]

    with threadpool_limits(limits=2, user_api="blas"):
        before = blas_threads()
        inside = _blas_on_one_thread(blas_threads)()
        assert inside and all(n == 1 for n in inside)
        assert blas_threads() == before
    assert _thread_pools() is _thread_pools()
