"""The compiled inverse-kinematics functions against finite differences and the general NumPy path."""

from __future__ import annotations

import numpy as np
import pytest

from vgtarm import paths
from vgtarm.ik.effort import effort_terms
from vgtarm.ik.options import IKOptions
from vgtarm.ik.problem import BatchState, IKProblem, Task
from vgtarm.ik.rates import exact
from vgtarm.ik.solve import _task

from .conftest import assert_close, central_difference, random_configurations


def position_task(robot, n: int) -> Task:
    """The position task of ``n`` samples of case 1 (the targets do not matter for these tests)."""
    return _task(robot, paths.case1(0.01, duration=0.01 * (n - 1)), None)


def test_hessian_of_the_constraint_lagrangian(robot):
    q = random_configurations(robot, 20, seed=5)
    lam = np.random.default_rng(1).normal(size=(20, 3))
    task = position_task(robot, 20)
    idx = np.arange(20)
    _, J, H = task.evaluate(idx, q, lam)
    assert_close(J, robot.tip_jacobian(q), rtol=1e-12, atol=1e-14)

    def gradient(x):
        return np.einsum("nij,ni->nj", task.evaluate(idx, x, lam)[1], lam)

    assert_close(H, central_difference(gradient, q), rtol=1e-6, atol=1e-7)
    assert_close(H, H.transpose(0, 2, 1), rtol=1e-12, atol=1e-13)


def test_second_directional_derivative(robot):
    rng = np.random.default_rng(2)
    q = random_configurations(robot, 10, seed=6)
    lam, qd, lam_d = rng.normal(size=(10, 3)), 0.05 * rng.normal(size=(10, 7)), rng.normal(size=(10, 3))
    (d2,) = robot.backend.evaluate("ik_position_d2", [q, lam, qd, lam_d, robot.parameter_vector], 10)
    task = position_task(robot, 10)

    def F(s):
        z_q, z_lam = q + s * qd, lam + s * lam_d
        c, J, _ = task.evaluate(np.arange(10), z_q, z_lam)
        return np.concatenate([np.einsum("nij,ni->nj", J, z_lam), c], axis=1)

    h = 1e-3  # about eps**(1/4) in joint space once scaled by |qd|: second differences
    assert_close(d2, (F(h) - 2 * F(0) + F(-h)) / h**2, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("criterion", ["joint_limits", "effort"])
def test_fused_rates_match_the_general_path(robot, criterion):
    """The compiled rates (``ik_*_rates``) equal the general path (``ik_*_dt``/``_d2`` and NumPy solves)."""
    path = paths.case2(0.05) if criterion == "effort" else paths.case1(0.05)
    options = {"criterion": "effort", "tool_force": 20.0} if criterion == "effort" else {}
    result = robot.inverse_kinematics(path, **options)
    effort = criterion == "effort"
    defaults = IKOptions(criterion="effort")
    problem = IKProblem.from_parameters(
        robot.parameters, joint_limit_weight=defaults.joint_limit_weight if effort else 1.0
    )
    terms = effort_terms(robot, path, 20.0, defaults.tool_force_speed) if effort else None
    task = _task(robot, path, None, terms)
    n = len(path)
    idx = np.arange(n)
    fused = task.evaluate_with_rates(idx, result.q, result.samples.multipliers, problem.weight)
    state = BatchState.empty(n, 3, 16, with_gradient=effort)
    state.q[:], state.lam[:] = result.q, result.samples.multipliers
    state.residual[:], state.J[:], state.H[:] = task.evaluate(idx, result.q, state.lam)
    exact(problem, task, state, idx)
    qd, _, qdd, _ = fused[4]
    assert_close(qd, state.qd, rtol=1e-9, atol=1e-12, what="qd")
    assert_close(qdd, state.qdd, rtol=1e-8, atol=1e-11, what="qdd")
    assert_close(qd, result.qd, rtol=1e-9, atol=1e-12)
