"""First- and second-order optimality of the inverse-kinematics solutions, with and without active limits."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from vgtarm import paths
from vgtarm.ik.problem import IKProblem

from .conftest import assert_close


def phi_gradient(robot, q: np.ndarray) -> np.ndarray:
    """``dPhi/dq`` of paper eq. 12, written out independently of the package."""
    lo, hi = robot.parameters.lower, robot.parameters.upper
    return 2.0 / 7.0 * (q - (lo + hi) / 2) / (hi - lo) ** 2


def test_projected_gradient_vanishes_where_no_bound_is_active(robot):
    result = robot.inverse_kinematics(paths.case1(0.02))
    assert not result.samples.active.any()
    J = robot.tip_jacobian(result.q)
    g = phi_gradient(robot, result.q)
    for i in range(0, len(result), 7):
        Z = scipy.linalg.null_space(J[i])
        assert Z.shape == (7, 4)
        assert np.abs(Z.T @ g[i]).max() <= 1e-9, f"sample {i}"


def test_second_order_condition_holds_on_the_null_space(robot):
    """A small step along the constraint manifold never lowers Phi (strict local minimum)."""
    path = paths.case2(0.1)
    result = robot.inverse_kinematics(path)
    problem = IKProblem.from_parameters(robot.parameters)
    rng = np.random.default_rng(0)
    for i in range(0, len(result), 5):
        q0 = result.q[i]
        Z = scipy.linalg.null_space(robot.tip_jacobian(q0))
        for _ in range(4):
            direction = Z @ rng.normal(size=Z.shape[1])
            q = q0 + 1e-3 * direction / np.linalg.norm(direction)
            for _ in range(8):  # Newton projection back onto P(q) = x (minimum-norm correction)
                J = robot.tip_jacobian(q)
                q = q - np.linalg.pinv(J) @ (robot.tip_position(q) - path.position[i])
            assert problem.phi(q) > problem.phi(q0)
    assert (result.samples.curvature > 0).all()


@pytest.fixture(scope="module")
def stretched(robot):
    """A path that lifts the tip until leg s2 reaches its upper limit (the bound becomes active)."""
    path = paths.waypoints([0.0, 1.0], [(0.0, 0.0, 0.66), (0.0, 0.0, 0.80)], dt=0.01, blend="quintic")
    return path, robot.inverse_kinematics(path)


def test_a_bound_becomes_active_and_is_respected(robot, stretched):
    path, result = stretched
    assert result.success, result.message
    upper_s2 = result.samples.constraint_labels.index("s2 <= max")
    active = result.samples.active[:, upper_s2]
    assert active[-1] and not active[0]
    assert_close(result.q[active, 3], robot.parameters.upper[3], rtol=0, atol=0, what="s2 on its limit")
    assert (result.q <= robot.parameters.upper + 1e-12).all() and (result.q >= robot.parameters.lower - 1e-12).all()
    assert_close(robot.tip_position(result.q), path.position, rtol=0, atol=1e-9)


def test_multiplier_of_an_active_bound_has_the_right_sign(robot, stretched):
    """Recompute the multipliers from scratch: grad Phi + J^T lam + mu e_s2 = 0 needs mu >= 0 (upper bound)."""
    _, result = stretched
    upper_s2 = result.samples.constraint_labels.index("s2 <= max")
    active = np.flatnonzero(result.samples.active[:, upper_s2])
    J = robot.tip_jacobian(result.q)
    g = phi_gradient(robot, result.q)
    e = np.zeros(7)
    e[3] = 1.0
    for i in active:
        A = np.column_stack([J[i].T, e])
        y, *_ = np.linalg.lstsq(A, -g[i], rcond=None)
        assert np.abs(A @ y + g[i]).max() <= 1e-9, "stationarity with the active bound"
        assert y[3] > 0.0, "the upper limit pushes back"
        assert_close(y[3], result.samples.inequality_multipliers[i, upper_s2], rtol=1e-6, atol=1e-10)
    # Where the bound is active the gradient is not orthogonal to the null space of J alone.
    Z = scipy.linalg.null_space(J[active[-1]])
    assert np.abs(Z.T @ g[active[-1]]).max() > 1e-6


def test_active_assembly_rows_keep_the_margin(robot):
    path = paths.waypoints([0.0, 1.0], [(0.0, 0.0, 0.66), (0.0, 0.0, 0.50)], dt=0.02, blend="quintic")
    result = robot.inverse_kinematics(path)
    assert result.success, result.message
    rows = result.samples.active_assembly
    assert rows.any()
    p = robot.parameters
    s, pp = result.q[:, 0], result.q[:, 2]
    margin = s + 2 * p.d[0] - pp
    assert_close(margin[rows[:, 0]], result.margin, rtol=0, atol=1e-12, what="s1 + 2d - p1 = margin where active")
    assert (margin >= result.margin - 1e-12).all()
    assert (result.samples.inequality_multipliers[:, 14:][rows] >= 0).all()
