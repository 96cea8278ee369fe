"""Switching control's GA predicts with the actuators' saturation (``ga_kernel_saturate`` and
``ga_dynamics_row`` in ``model/csrc/vgt_ga.h``, ``vgt_ga_fitness_limited`` in ``closed_loop.c``).

The exact prediction with actuators is held to its NumPy twin (:func:`vgtarm.control.
predict_tip_error` with ``actuators``); the dynamics rows to the model's own mass matrix and inverse
dynamics; the single-precision lanes (linear and quadratic) to the exact prediction on candidates
whose efforts are clipped for most of the window; and limits that never bind leave the lanes'
prediction bit for bit as it is without actuators.
"""

from __future__ import annotations

import numpy as np
import pytest

from vgtarm.control import SwitchingControl, predict_tip_error
from vgtarm.model.actuators import Actuator, Actuators
from vgtarm.model.closedloop import PREDICTIONS, ClosedLoopDriver
from vgtarm.model.compiled import CompiledBackend
from vgtarm.model.parameters import JOINT_NAMES
from vgtarm.simulation.engines import compiled_ga
from vgtarm.simulation.simulator import loop_arrays

from .conftest import assert_close
from .test_ga_compiled import reference


@pytest.fixture(scope="module")
def compiled(robot):
    if not isinstance(robot.backend, CompiledBackend):
        pytest.skip("no C compiler: the compiled GA is not built")
    return robot


def _actuators(n: int, force: float, speed: float, line: bool) -> Actuators:
    """Every leg the same actuator, the last joint (the twist) 2 N m: the first ``n`` names."""
    joints = tuple(Actuator(force, speed, force_speed=line) for _ in range(n - 1)) + (Actuator(2.0, 10.0),)
    return Actuators(JOINT_NAMES[:n], joints)


def _limits(actuators: Actuators):
    return actuators.force, actuators.speed, actuators.force_speed.astype(float)


def _window(robot, scm, actuators):
    ref = reference(robot, duration=0.1)
    arrays = loop_arrays(robot, robot, ref, initial_state=(ref.q[0], ref.qd[0]))
    ga = compiled_ga(scm, ClosedLoopDriver(robot.backend), robot, arrays, ref.dt)
    limited = type(ga)(
        ClosedLoopDriver(robot.backend),
        scm,
        dt=ref.dt,
        p_ctrl=robot.parameter_vector,
        reference=arrays.inputs,
        actuators=None if actuators is None else _limits(actuators),
    )
    return ref, ga, limited


def _candidates(scm, rng, count=24):
    lower, upper = scm.bounds()
    genes = lower + 0.3 * rng.random((count, len(lower))) * (upper - lower)
    genes[0] = np.concatenate([scm.fixed.Kp.ravel(), scm.fixed.Kv.ravel()])
    return genes


def _start(robot, ref, k, rng):
    n = robot.n_joints
    return ref.q[k] + rng.normal(scale=3e-4, size=n), ref.qd[k] + rng.normal(scale=3e-3, size=n)


SCM = dict(variant="paper", kp_bounds=(0, 15000), kv_bounds=(0, 600), exact_above=0.0)


@pytest.mark.parametrize("line", [False, True])
def test_exact_prediction_with_actuators_is_its_numpy_twin(compiled, line):
    """Compiled (cfc -> clip and force-speed line -> forward dynamics, Euler) against NumPy
    (M a + C -> Actuators.saturate -> Robot.forward_dynamics): the same to 1e-10 relative; and the
    clip binds (the costs differ from those without actuators)."""
    robot = compiled
    scm = SwitchingControl.with_gains(5000.0, 300.0, **SCM)
    actuators = _actuators(robot.n_joints, 25.0, 0.05, line)
    ref, free, limited = _window(robot, scm, actuators)
    rng = np.random.default_rng(3)
    genes = _candidates(scm, rng)
    k = 30
    q0, qd0 = _start(robot, ref, k, rng)
    limited._ga.prediction = free._ga.prediction = PREDICTIONS["exact"]
    ours = limited.predict(k, q0, qd0, genes)
    without = free.predict(k, q0, qd0, genes)
    window = slice(k, k + scm.horizon + 1)
    Kp, Kv = scm.split(genes)
    tip_d = robot.tip_position(ref.q[window])
    twin = predict_tip_error(
        robot, ref.dt, q0, qd0, ref.q[window], ref.qd[window], ref.qdd[window], tip_d, Kp, Kv, actuators
    )
    finite = np.isfinite(twin)
    assert finite.sum() >= len(genes) // 2
    assert np.array_equal(np.isfinite(ours), finite)
    assert_close(ours[finite], twin[finite], rtol=1e-10, atol=0)
    changed = np.abs(ours[finite] - without[finite]) > 1e-3 * without[finite]
    assert changed.mean() > 0.5, "the clip should bind on most candidates"


def test_dynamics_rows_are_the_models(compiled):
    """The rows the prediction reads: F_d the inverse dynamics, M_d the mass matrix, M_d^-1 its inverse."""
    robot = compiled
    scm = SwitchingControl.with_gains(5000.0, 300.0, **SCM)
    ref, _, limited = _window(robot, scm, _actuators(robot.n_joints, 25.0, 0.05, True))
    limited._ga.prediction = PREDICTIONS["linear"]
    k = 10
    limited.predict(k, ref.q[k], ref.qd[k], _candidates(scm, np.random.default_rng(0), 2))
    rows = slice(k, k + scm.horizon + 1)
    arrays = limited._arrays
    q, qd, qdd = ref.q[rows], ref.qd[rows], ref.qdd[rows]
    assert_close(arrays["F_d"][rows], robot.inverse_dynamics(q, qd, qdd), rtol=1e-12, atol=1e-12)
    M = robot.mass_matrix(q)
    assert_close(arrays["M_d"][rows], M, rtol=1e-10, atol=1e-12)
    eye = np.broadcast_to(np.eye(robot.n_joints), M.shape)
    assert_close(arrays["Minv_d"][rows] @ M, eye, rtol=0, atol=1e-10)
    # dID/dqd against central differences of a small step (the row's step is a whole unit: exact
    # for an effort quadratic in qd), its diagonal about the viscous friction (N s/m)
    h, j = 1e-6, 3
    n = robot.n_joints
    columns = [
        (robot.inverse_dynamics(q[j], qd[j] + h * e, qdd[j]) - robot.inverse_dynamics(q[j], qd[j] - h * e, qdd[j]))
        / (2 * h)
        for e in np.eye(n)
    ]
    assert_close(arrays["D_d"][k + j], np.array(columns).T, rtol=1e-6, atol=1e-6)
    assert_close(np.diag(arrays["D_d"][k + j]), robot.parameters.viscous, rtol=0, atol=10.0)


@pytest.mark.parametrize("prediction", ["linear", "quadratic"])
def test_lanes_follow_the_exact_prediction_under_saturation(compiled, prediction):
    """Efforts clipped over most of the window: the single-precision lanes, linearised about the
    reference, rank the candidates as the exact prediction does and stay near its costs; without
    the saturation in the lanes they would be far off (the gains' accelerations are not delivered)."""
    robot = compiled
    scm = SwitchingControl.with_gains(5000.0, 300.0, **SCM)
    actuators = _actuators(robot.n_joints, 25.0, 0.05, True)
    ref, free, limited = _window(robot, scm, actuators)
    rng = np.random.default_rng(11)
    genes = _candidates(scm, rng, 40)
    k = 40
    q0, qd0 = _start(robot, ref, k, rng)
    limited._ga.prediction = PREDICTIONS["exact"]
    exact = limited.predict(k, q0, qd0, genes)
    limited._ga.prediction = free._ga.prediction = PREDICTIONS[prediction]
    lanes = limited.predict(k, q0, qd0, genes)
    unsaturated = free.predict(k, q0, qd0, genes)
    ok = np.isfinite(exact) & (exact < 1.0)
    assert ok.sum() >= 20
    error = np.abs(lanes[ok] - exact[ok]) / exact[ok]
    error_free = np.abs(unsaturated[ok] - exact[ok]) / exact[ok]
    assert np.median(error) < 0.02, np.median(error)
    assert np.median(error_free) > 5 * np.median(error), (np.median(error_free), np.median(error))
    ranks = np.argsort(np.argsort(exact[ok]))
    lane_ranks = np.argsort(np.argsort(lanes[ok]))
    assert np.corrcoef(ranks, lane_ranks)[0, 1] > 0.9


def test_limits_that_never_bind_leave_the_lanes_bit_for_bit(compiled):
    """Limits far above every effort: the lanes skip the correction (nothing clipped), so the
    prediction is exactly the one without actuators."""
    robot = compiled
    scm = SwitchingControl.with_gains(5000.0, 300.0, **SCM)
    ref, free, limited = _window(robot, scm, _actuators(robot.n_joints, 1e6, 1e3, True))
    rng = np.random.default_rng(5)
    genes = _candidates(scm, rng)
    k = 25
    q0, qd0 = _start(robot, ref, k, rng)
    for name in ("linear", "quadratic"):
        limited._ga.prediction = free._ga.prediction = PREDICTIONS[name]
        assert np.array_equal(limited.predict(k, q0, qd0, genes), free.predict(k, q0, qd0, genes))


def test_the_ga_in_the_loop_and_per_activation_predict_with_the_same_actuators(compiled, monkeypatch):
    """Switching control on a robot whose lines bind along the path (no-load speed 0.08 m/s, the
    reference up to 0.06 m/s): the GA called inside the compiled loop and the one called from
    Python per activation get the run's actuators alike, so the runs are the same to the last bit;
    and the activations' predictions are those with the saturation (they differ from a GA told of
    no actuators on the same states)."""
    from dataclasses import replace

    from vgtarm.simulation import ExternalForce, engines, simulate

    robot = compiled
    actuators = _actuators(robot.n_joints, 200.0, 0.08, True)
    limited = robot.with_parameters(replace(robot.parameters, actuators=actuators))
    ref = reference(robot, duration=0.06)
    scm = SwitchingControl.with_gains(5000.0, 300.0, variant="paper", threshold=1.2e-4)
    options = dict(external_force=ExternalForce(), seed=7, encoder_resolution=1e-6, substeps=4)
    runs = []
    for in_loop in (True, False):
        monkeypatch.setattr(engines, "GA_IN_LOOP", in_loop)
        runs.append(simulate(limited, ref, scm, **options))
    inside, outside = runs
    assert len(inside.activations) > 3
    for name in ("q", "qd", "effort", "mode"):
        np.testing.assert_array_equal(getattr(inside, name), getattr(outside, name))
    fitness = [(a.best_fitness, a.fixed_gains_fitness) for a in inside.activations]
    assert fitness == [(a.best_fitness, a.fixed_gains_fitness) for a in outside.activations]
    # a GA told of no actuators (the plant still has them) predicts other costs on the same states
    monkeypatch.setattr(engines, "_limits", lambda settings, inputs: None)
    blind = simulate(limited, ref, scm, **options)
    first, other = inside.activations[0], blind.activations[0]
    assert first.sample == other.sample  # the same run up to the first activation
    assert first.fixed_gains_fitness != other.fixed_gains_fitness
