"""The model-based state estimate (``estimator="kalman"``, docs/control.md)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

import vgtarm
from vgtarm.model.closedloop import ClosedLoopDriver, LoopSettings
from vgtarm.model.compiled import InterpretedBackend, build_functions
from vgtarm.simulation import ExternalForce, simulate
from vgtarm.simulation.sensing import kalman_gains
from vgtarm.simulation.simulator import loop_arrays

from .conftest import assert_close
from .test_observer import CFC, reference

KALMAN = {"encoder_resolution": 1e-6, "estimator": "kalman", "estimator_bandwidth_hz": 100.0}


def test_gains_are_those_of_the_steady_state_riccati_solution():
    dt = 1e-3
    L = np.array(kalman_gains(dt, 100.0))
    # the steady-state posterior gain is a fixed point of predict + update with the same gain
    A = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    closed = (np.eye(3) - np.outer(L, [1.0, 0.0, 0.0])) @ A
    assert np.max(np.abs(np.linalg.eigvals(closed))) < 1.0  # the error dynamics are stable
    assert 0 < L[0] < 1 and L[1] > 0 and L[2] > 0
    slower = np.array(kalman_gains(dt, 30.0))
    assert np.all(slower < L)  # a lower bandwidth trusts the model more


def test_compiled_loop_matches_its_numpy_twin_with_the_kalman_estimator(robot):
    slow = vgtarm.Robot(robot.parameters, InterpretedBackend(build_functions()))
    ref = reference(robot, duration=0.08)
    kwargs = dict(external_force=ExternalForce(), seed=5, controller_model=robot.parameters.scaled(mass=1.1))
    for observer in ("momentum", "none"):
        fast = simulate(robot, ref, CFC, observer=observer, **KALMAN, **kwargs)
        twin = simulate(slow, ref, CFC, observer=observer, **KALMAN, **kwargs)
        assert fast.success and twin.success
        for name in ("q", "qd", "effort", "tip_error"):
            assert_close(getattr(fast, name), getattr(twin, name), rtol=1e-9, atol=1e-12, what=f"{observer} {name}")
        if observer == "momentum":
            assert_close(fast.effort_estimate, twin.effort_estimate, rtol=1e-9, atol=1e-9, what="effort_estimate")
    assert fast.metadata["estimator"] == "kalman" and fast.metadata["estimator_bandwidth_hz"] == 100.0


def test_the_estimate_converges_on_a_known_trajectory_and_a_constant_push(robot):
    """Exact model, fine encoders: from a wrong start the estimated velocity converges to the true
    one; a constant tip force is found as the disturbance (J_P^T f) by the momentum observer."""
    dt, n = 1e-3, 201
    ref = reference(robot, duration=(n - 1) * dt, amplitude=np.zeros(7))
    force = np.array([3.0, -5.0, -20.0])
    arrays = loop_arrays(
        robot, robot, ref, np.tile(force, (n, 1)), initial_state=(ref.q[0], ref.qd[0]), resolution=np.full(7, 1e-9)
    )
    settings = LoopSettings(
        dt=dt,
        integrator="euler",
        substeps=1,
        cutting=False,
        cutting_force=0.0,
        cutting_speed=ExternalForce().cutting_speed,
        threshold=0.0,
        limit_tolerance=0.05,
        observer="momentum",
        observer_gain=1.0 / dt,
        sensing=True,
        velocity_filter=math.exp(-2 * math.pi * 100.0 * dt),
        estimator="kalman",
        kalman_gain=kalman_gains(dt, 100.0),
    )
    status, _ = ClosedLoopDriver(robot.backend).simulate(settings, arrays, CFC.gains.Kp, CFC.gains.Kv, 0, n)
    assert status == 0
    tau_ext = np.einsum("kij,ki->kj", robot.tip_jacobian(arrays.q), arrays.f_ext)
    late = slice(150, n)
    # the disturbance estimate M^ d^ through the observer's filter: J_P^T f to 0.5 %
    gap = np.max(np.linalg.norm(arrays.tau_hat[late] - tau_ext[late], axis=1)) / np.linalg.norm(tau_ext[-1])
    assert gap < 5e-3
    # the velocity the controller sees follows the true one (the push moved the arm first)
    assert np.max(np.abs(arrays.qd_meas[late] - arrays.qd[late])) < 1e-4


def test_a_sliced_kalman_run_is_the_same_bit_for_bit(robot):
    ref = reference(robot, duration=0.1)
    options = dict(external_force=ExternalForce(), seed=2, observer="momentum", **KALMAN)
    whole = simulate(robot, ref, CFC, **options)
    chunked = simulate(robot, ref, CFC, progress=lambda done, total: None, **options)
    for name in ("q", "effort", "effort_estimate"):
        np.testing.assert_array_equal(getattr(whole, name), getattr(chunked, name), err_msg=name)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"estimator": "luenberger"}, "estimator = 'luenberger': expected one of ['difference', 'kalman']"),
        ({"estimator": "kalman"}, "estimator = 'kalman' without encoders: expected encoder_resolution > 0"),
        ({"estimator_bandwidth_hz": 50.0}, "estimator_bandwidth_hz = 50.0: only used with estimator = 'kalman'"),
        ({**KALMAN, "estimator_bandwidth_hz": 400.0}, "estimator_bandwidth_hz = 400.0: expected at most 0.25/dt"),
        ({**KALMAN, "estimator_bandwidth_hz": -1.0}, "estimator_bandwidth_hz = -1.0: expected a finite number > 0"),
        ({**KALMAN, "velocity_noise": 1e-4}, "velocity_noise = 0.0001 with estimator = 'kalman': expected 0"),
    ],
)
def test_bad_estimator_arguments_are_one_clear_line(robot, kwargs, message):
    with pytest.raises(vgtarm.InputError, match=re.escape(message)) as info:
        simulate(robot, reference(robot, duration=0.01), CFC, **kwargs)
    assert "\n" not in str(info.value)
