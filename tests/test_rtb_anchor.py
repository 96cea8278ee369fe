"""Robotics Toolbox's ``IK_LM`` on a vgtarm robot (benchmarks/rtb_anchor.py, issue 36 item 5).

The adapter hands vgtarm's forward kinematics and Jacobians to RTB's Python IK solvers; checked here
against the forward kinematics and against central differences of it. RTB's masked
Levenberg-Marquardt then solves the vertical tool-axis task independently of vgtarm's IK: it must
reach the target, and its joint-limit cost ``Phi`` (which it does not minimise) can be no lower
than that of vgtarm's ``solve_point`` (which does).
"""

from __future__ import annotations

import numpy as np
import pytest

import vgtarm
from vgtarm.ik import solve_point
from vgtarm.ik.problem import IKProblem

from .conftest import FD_STEP, random_configurations

pytest.importorskip("roboticstoolbox", reason="Robotics Toolbox is optional: pip install 'vgtarm[bench]' to run these")

from benchmarks.rtb_anchor import VgtEts, axis_angle, solve_masked, targets  # noqa: E402

UP = np.array([0.0, 0.0, 1.0])


def _middle(robot: vgtarm.Robot, n: int, seed: int) -> np.ndarray:
    """``n`` configurations in the middle half of each joint's range, assemblable with 1 cm margin."""
    rng = np.random.default_rng(seed)
    low, high = robot.joint_limits()
    chosen: list[np.ndarray] = []
    while len(chosen) < n:
        q = low + (0.25 + 0.5 * rng.random(robot.n_joints)) * (high - low)
        if robot.is_assemblable(q, 0.01):
            chosen.append(q)
    return np.stack(chosen)


def _vee(S: np.ndarray) -> np.ndarray:
    """The vector of the skew-symmetric part of ``S`` ``(3, 3)``."""
    A = 0.5 * (S - S.T)
    return np.array([A[2, 1], A[0, 2], A[1, 0]])


def test_eval_is_the_tool_frame(robot: vgtarm.Robot) -> None:
    ets = VgtEts(robot)
    assert ets.n == robot.n_joints and ets.qlim.shape == (2, robot.n_joints)
    for q in random_configurations(robot, 5, seed=1):
        point, rotation = robot.tool_frame(q)
        T = ets.eval(q)
        np.testing.assert_array_equal(T[:3, :3], rotation)
        np.testing.assert_array_equal(T[:3, 3], point)
        np.testing.assert_array_equal(T[3], [0.0, 0.0, 0.0, 1.0])


def _differences(ets: VgtEts, q: np.ndarray, j: int, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Central differences along joint ``j``: of the tip point and ``vee(dR/dq_j R^T)``."""
    e = np.zeros(ets.n)
    e[j] = h
    plus, minus, R = ets.eval(q + e), ets.eval(q - e), ets.eval(q)[:3, :3]
    return (plus[:3, 3] - minus[:3, 3]) / (2 * h), _vee((plus[:3, :3] - minus[:3, :3]) / (2 * h) @ R.T)


def test_jacob0_is_central_differences_of_the_pose(robot: vgtarm.Robot) -> None:
    """Linear rows first (RTB's order): ``dP/dq``; then the angular velocity, ``vee(dR/dq_j R^T)``.

    The angular entries reach ~10 rad/m with large third derivatives, so the differences at
    ``FD_STEP`` and half of it are Richardson-extrapolated (error ``O(h^4)``) to hold 1e-7."""
    ets = VgtEts(robot)
    for q in random_configurations(robot, 5, seed=2):
        J = ets.jacob0(q)
        for j in range(robot.n_joints):
            (p1, w1), (p2, w2) = _differences(ets, q, j, FD_STEP), _differences(ets, q, j, FD_STEP / 2)
            np.testing.assert_allclose(J[:3, j], (4 * p2 - p1) / 3, atol=1e-7, rtol=0)
            np.testing.assert_allclose(J[3:, j], (4 * w2 - w1) / 3, atol=1e-7, rtol=0)


def test_a_non_configuration_is_far_and_ends_the_search(robot: vgtarm.Robot) -> None:
    """A ``q`` that cannot be assembled: a finite pose 1 km away, and a Jacobian RTB gives up on."""
    rng = np.random.default_rng(3)
    low, high = robot.joint_limits()
    q = next(q for q in rng.uniform(low, high, (1000, robot.n_joints)) if not robot.is_assemblable(q))
    ets = VgtEts(robot)
    T = ets.eval(q)
    assert np.isfinite(T).all() and np.linalg.norm(T[:3, 3]) > 100.0
    with pytest.raises(np.linalg.LinAlgError, match="not a configuration"):
        ets.jacob0(q)
    assert (ets.invalid_evaluations, ets.abandoned_searches) == (1, 1)


def _check_answer(robot: vgtarm.Robot, point: np.ndarray, q: np.ndarray) -> None:
    low, high = robot.joint_limits()
    assert np.all((low <= q) & (q <= high))
    assert np.linalg.norm(robot.tip_position(q) - point) <= 1e-9
    assert axis_angle(robot, q, UP) <= 1e-9
    ours = solve_point(robot, point, axis=UP)
    assert ours.success
    phi = float(IKProblem.from_parameters(robot.parameters).phi(q))
    assert phi >= ours.phi - 1e-12


def test_solve_masked_reaches_home_with_the_axis_vertical(robot: vgtarm.Robot) -> None:
    """The home pose's tool axis is vertical, so its tip with the axis vertical is reachable; from a
    random start RTB reaches it."""
    home = np.asarray(robot.parameters.home, dtype=float)
    assert axis_angle(robot, home, UP) <= 1e-12
    point = robot.tip_position(home)
    for q0 in _middle(robot, 3, seed=4):
        q, success, iterations, seconds = solve_masked(robot, point, q0, seed=0)
        assert success and iterations > 0 and seconds > 0.0
        _check_answer(robot, point, q)


def test_solve_masked_reaches_seeded_targets_and_repeats(robot: vgtarm.Robot) -> None:
    home = np.asarray(robot.parameters.home, dtype=float)
    points, solutions, _ = targets(robot, 3, seed=5)
    assert all(s.success for s in solutions)
    for i, point in enumerate(points):
        q, success, _, _ = solve_masked(robot, point, home, seed=i)
        assert success
        _check_answer(robot, point, q)
        np.testing.assert_array_equal(solve_masked(robot, point, home, seed=i).q, q)
