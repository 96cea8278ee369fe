"""The inverse kinematics of a long arm (issue 24, issue 27 item 1): minima, not saddles.

On ``examples/tapered_thirty.toml`` (30 modules, straight at home) the Newton iteration of the fast
solver used to stop on the first samples of case 2 at KKT points that are saddles of the cost on
the task (the straight branch that a buckling arm leaves behind: reduced Hessian indefinite), which
the verification rightly refused. The iteration now leaves such points along their directions of
negative curvature (:func:`vgtarm.ik.newton.curvature_step`). Checked here against what does not
use the solver's own KKT code: the forward kinematics of every answer, the eigenvalues of the
reduced Hessian computed here, and SLSQP on the problem written from the forward kinematics alone,
started from perturbed answers (it finds no lower cost nearby).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import null_space
from scipy.optimize import minimize

import vgtarm
from vgtarm.experiment.cases import case_path
from vgtarm.ik import newton

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.fixture(scope="module")
def tapered() -> vgtarm.Robot:
    return vgtarm.load_robot(EXAMPLES / "tapered_thirty.toml")


@pytest.fixture(scope="module")
def case2(tapered: vgtarm.Robot):
    path = case_path(tapered, 2, dt=0.05)
    return path, tapered.inverse_kinematics(path)


def _cost(robot: vgtarm.Robot, q: np.ndarray) -> float:
    p = robot.parameters
    return float(np.sum(((q - (p.lower + p.upper) / 2) / (p.upper - p.lower)) ** 2)) / q.shape[-1]


def test_case2_every_sample_verified_on_the_target(tapered, case2) -> None:
    path, ik = case2
    assert ik.success, ik.message
    assert set(ik.samples.method.tolist()) == {"newton"}  # no fallback needed
    tips = tapered.tip_position(np.asarray(ik.q))
    assert np.abs(tips - path.position).max() <= 1e-10
    assert (ik.samples.curvature > 0).all()


@pytest.mark.parametrize("i", [0, 20])
def test_first_samples_are_minima(tapered, case2, i: int) -> None:
    """The samples that were saddles: reduced Hessian of the cost on the task, by finite differences of the
    tip Jacobian (written here), positive definite; SLSQP from perturbed answers finds no lower cost."""
    path, ik = case2
    q = np.array(ik.q[i])
    p = tapered.parameters
    n = q.shape[0]
    weight = 2.0 / (n * (p.upper - p.lower) ** 2)
    lam = np.array(ik.samples.multipliers[i])
    J = tapered.tip_jacobian(q)
    step = 1e-6
    # Hessian of lam^T P(q): central differences of J^T lam
    columns = [
        (tapered.tip_jacobian(q + step * e).T @ lam - tapered.tip_jacobian(q - step * e).T @ lam) / (2 * step)
        for e in np.eye(n)
    ]
    W = np.diag(weight) + np.array(columns).T
    Z = null_space(J)
    smallest = np.linalg.eigvalsh(Z.T @ ((W + W.T) / 2) @ Z)[0]
    assert smallest > 1e-4 * weight.mean()
    G, h = p.margin_form()
    rng = np.random.default_rng(i)
    best = _cost(tapered, q)
    for _ in range(3):
        start = np.clip(q + 0.01 * (Z @ rng.standard_normal(Z.shape[1])), p.lower, p.upper)
        result = minimize(
            lambda x: _cost(tapered, x),
            start,
            jac=lambda x: 2 * (x - (p.lower + p.upper) / 2) / (p.upper - p.lower) ** 2 / n,
            method="SLSQP",
            bounds=list(zip(p.lower, p.upper, strict=True)),
            constraints=[
                {
                    "type": "eq",
                    "fun": lambda x: tapered.tip_position(x) - path.position[i],
                    "jac": lambda x: tapered.tip_jacobian(x),
                },
                {"type": "ineq", "fun": lambda x: G @ x + h - ik.margin, "jac": lambda x: G},
            ],
            options={"ftol": 1e-14, "maxiter": 500},
        )
        assert np.abs(tapered.tip_position(result.x) - path.position[i]).max() < 1e-8
        assert result.fun >= best - 1e-9, (result.fun, best)


class _Toy:
    """The parts of an :class:`~vgtarm.ik.problem.IKProblem` the curvature step reads: three joints, a
    cost ``q^T diag(1, -2, 1) q / 2`` (a saddle at zero; unit weights for the scales), no triangle row."""

    n, n_triangle = 3, 0
    weight = np.ones(3)

    def phi_gradient(self, q: np.ndarray) -> np.ndarray:
        return q * np.array([1.0, -2.0, 1.0])


def test_curvature_step_leaves_a_saddle() -> None:
    """One task row ``q3 = 0``; the Hessian of the Lagrangian is ``diag(1, -2, 1)``: on the task's null
    space (``q1``, ``q2``) the point ``q = 0`` is a saddle. It is detected, and the step from it goes along
    ``q2`` (the negative curvature) by the smallest escape length, keeps the task and does not move ``q1``;
    a step from ``q2 = 0.3`` goes further away from the saddle (downhill), by ``0.3``: the distance doubles."""
    toy = _Toy()
    W = np.diag([1.0, -2.0, 1.0])[None]
    J = np.array([[[0.0, 0.0, 1.0]]])
    active = np.zeros((1, 6), dtype=bool)
    assert newton.negative_curvature(toy, W, J, active).tolist() == [True]  # type: ignore[arg-type]
    assert newton.negative_curvature(toy, np.diag([1.0, 2.0, -5.0])[None], J, active).tolist() == [False]  # type: ignore[arg-type]
    max_step = 0.02
    x = newton.curvature_step(toy, np.zeros((1, 3)), W, J, np.zeros((1, 1)), None, max_step)  # type: ignore[arg-type]
    dq = x[0, :3]
    assert abs(abs(dq[1]) - newton.ESCAPE_FRACTION * max_step) < 1e-15 and abs(dq[0]) < 1e-15 and abs(dq[2]) < 1e-15
    # away from the saddle: the gradient along q2 is -2 * 0.3; the step is -g / |curvature| = +0.3
    q = np.array([[0.0, 0.3, 0.0]])
    x = newton.curvature_step(toy, q, W, J, np.zeros((1, 1)), None, max_step)  # type: ignore[arg-type]
    np.testing.assert_allclose(x[0, :3], [0.0, 0.3, 0.0], atol=1e-15)
    # the new multiplier makes the Lagrangian stationary along the task row (q3): zero here
    assert abs(x[0, 3]) < 1e-15


def test_coarse_step_scales_with_the_reach_only_beyond_the_papers() -> None:
    """The default coarse step: exactly 0.02 m up to the paper robot's reach, in proportion beyond it;
    the paper's robot's IK of case 1 with the default equals the one with 0.02 m given, bit for bit."""
    from vgtarm import paths
    from vgtarm.ik.options import COARSE_STEP, PAPER_REACH, default_coarse_step

    assert default_coarse_step(PAPER_REACH) == COARSE_STEP == 0.02
    assert default_coarse_step(0.3) == COARSE_STEP
    assert default_coarse_step(PAPER_REACH + 1e-12) == COARSE_STEP
    assert default_coarse_step(23.5 * PAPER_REACH) == pytest.approx(23.5 * COARSE_STEP, rel=1e-15)
    robot = vgtarm.load_robot()
    path = paths.case1(dt=4e-3)
    default, given = robot.inverse_kinematics(path), robot.inverse_kinematics(path, coarse_step=0.02)
    assert default.success and np.array_equal(default.q, given.q) and np.array_equal(default.qdd, given.qdd)
