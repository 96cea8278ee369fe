"""Exact reference rates: kinematic consistency, and agreement with finite differences as dt shrinks."""

from __future__ import annotations

import numpy as np
import pytest

from vgtarm import paths
from vgtarm.ik.rates import finite_difference

from .conftest import assert_close


@pytest.mark.parametrize("build", [paths.case1, paths.case2], ids=["case1", "case2"])
def test_rates_satisfy_the_velocity_and_acceleration_relations(robot, build):
    path = build(0.005)
    result = robot.inverse_kinematics(path)
    J = robot.tip_jacobian(result.q)
    velocity = np.einsum("nij,nj->ni", J, result.qd)
    bias = robot.bias_accelerations(result.q, result.qd).tip
    acceleration = np.einsum("nij,nj->ni", J, result.qdd) + bias
    scale_v = np.abs(path.velocity).max()
    scale_a = np.abs(path.acceleration).max()
    assert np.abs(velocity - path.velocity).max() <= 1e-8 * scale_v
    assert np.abs(acceleration - path.acceleration).max() <= 1e-8 * scale_a


def test_exact_rates_agree_with_central_differences_as_dt_shrinks(robot):
    """Central differences of the position solution converge to the exact rates as dt^2."""
    t_check = np.array([0.2, 0.3, 0.4])
    errors_v, errors_a = [], []
    for dt in (0.02, 0.01, 0.005):
        path = paths.case1(dt, duration=0.6)
        exact = robot.inverse_kinematics(path)
        fd = robot.inverse_kinematics(path, rates="finite_difference")
        k = np.rint(t_check / dt).astype(int)
        assert_close(fd.q, exact.q, rtol=0, atol=0)
        errors_v.append(np.abs(fd.qd[k] - exact.qd[k]).max())
        errors_a.append(np.abs(fd.qdd[k] - exact.qdd[k]).max())
    for errors in (errors_v, errors_a):
        ratios = np.array(errors[:-1]) / np.array(errors[1:])
        assert ((ratios > 3.5) & (ratios < 4.5)).all(), (errors, ratios)


def test_finite_difference_mode_is_central_inside_and_euler_at_the_ends():
    t = np.linspace(0.0, 1.0, 11)
    q = np.column_stack([t**3] * 7)
    qd, qdd = finite_difference(q, 0.1)
    assert_close(qd[5], (q[6] - q[4]) / 0.2)
    assert_close(qd[0], (q[1] - q[0]) / 0.1)
    assert_close(qd[-1], (q[-1] - q[-2]) / 0.1)
    assert_close(qdd[5], (q[6] - 2 * q[5] + q[4]) / 0.01)
    assert_close(qdd[0], (qd[1] - qd[0]) / 0.1)


def test_active_bound_keeps_its_joint_still(robot):
    path = paths.waypoints([0.0, 1.0], [(0.0, 0.0, 0.66), (0.0, 0.0, 0.80)], dt=0.01, blend="quintic")
    result = robot.inverse_kinematics(path)
    active = result.samples.active[:, 7 + 3]  # s2 <= max
    assert active.any()
    assert_close(result.qd[active, 3], 0.0, rtol=0, atol=0)
    assert_close(result.qdd[active, 3], 0.0, rtol=0, atol=0)
    J = robot.tip_jacobian(result.q)
    assert_close(np.einsum("nij,nj->ni", J, result.qd), path.velocity, rtol=0, atol=1e-10)


def test_fast_and_reference_rates_agree(robot):
    path = paths.case2(0.1)
    fast = robot.inverse_kinematics(path)
    reference = robot.inverse_kinematics(path, solver="reference")
    assert_close(fast.qd, reference.qd, rtol=0, atol=1e-6)
    assert_close(fast.qdd, reference.qdd, rtol=0, atol=1e-5)
