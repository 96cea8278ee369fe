"""Inverse kinematics (paper eq. 12): round trips, agreement of the fast and reference solvers, records."""

from __future__ import annotations

import numpy as np
import pytest

import vgtarm
from vgtarm import paths
from vgtarm.ik import IKResult, inverse_kinematics, solver_names
from vgtarm.ik.problem import IKProblem

from .conftest import assert_close, random_configurations

CASES = {"case1": paths.case1, "case2": paths.case2}


@pytest.fixture(scope="module")
def full_paths(robot) -> dict[str, tuple[paths.TipPath, IKResult]]:
    """Both case paths at the paper's 1 ms and their fast solution (computed once)."""
    solved = {}
    for name, build in CASES.items():
        path = build(1e-3)
        solved[name] = (path, robot.inverse_kinematics(path))
    return solved


def subsample(path: paths.TipPath, count: int) -> paths.TipPath:
    """``count`` evenly spaced samples of ``path`` as a path of its own (uniform times)."""
    step = (len(path) - 1) // (count - 1)
    idx = np.arange(count) * step
    return paths.TipPath(path.name, path.t[idx], path.position[idx], path.velocity[idx], path.acceleration[idx])


def point_path(x: np.ndarray) -> paths.TipPath:
    """A two-sample path holding the tip still at ``x``."""
    zeros = np.zeros((2, 3))
    return paths.TipPath("point", np.array([0.0, 1.0]), np.stack([x, x]), zeros, zeros)


@pytest.mark.parametrize("name", sorted(CASES))
def test_round_trip_on_the_case_paths(robot, full_paths, name):
    path, result = full_paths[name]
    assert result.success, result.message
    assert result.q.shape == result.qd.shape == result.qdd.shape == (len(path), 7)
    assert_close(robot.tip_position(result.q), path.position, rtol=0, atol=1e-9, what="P(IK(x)) = x")
    assert result.samples.residual.max() <= 1e-9
    p = robot.parameters
    assert (result.q >= p.lower - 1e-12).all() and (result.q <= p.upper + 1e-12).all()  # active-set tolerance
    assert robot.is_assemblable(result.q, margin=result.margin - 1e-12).all()


def test_round_trip_on_random_reachable_points(robot):
    q_random = random_configurations(robot, 12, seed=3, margin=0.01)
    targets = robot.tip_position(q_random)
    for x in targets:
        result = robot.inverse_kinematics(point_path(x))
        assert result.success, result.message
        assert_close(robot.tip_position(result.q), np.stack([x, x]), rtol=0, atol=1e-9, what=f"target {x}")
        # The optimum is never worse than the configuration that produced the target.
    problem = IKProblem.from_parameters(robot.parameters)
    reached = np.array([robot.inverse_kinematics(point_path(x)).samples.phi[0] for x in targets[:4]])
    assert (reached <= problem.phi(q_random[:4]) + 1e-12).all()


@pytest.mark.parametrize("name", sorted(CASES))
def test_fast_and_reference_reach_the_same_optimum(robot, full_paths, name):
    path, _ = full_paths[name]
    coarse = subsample(path, 41)
    fast = robot.inverse_kinematics(coarse)
    reference = robot.inverse_kinematics(coarse, solver="reference")
    assert fast.success and reference.success, (fast.message, reference.message)
    both = fast.samples.success & reference.samples.success
    assert_close(fast.samples.phi[both], reference.samples.phi[both], rtol=0, atol=1e-9, what="Phi")
    assert_close(fast.q, reference.q, rtol=0, atol=1e-5, what="q")
    assert reference.samples.residual.max() <= 1e-9
    assert set(reference.samples.method) == {"slsqp"}


def test_ipopt_reference_agrees(robot, full_paths):
    path, _ = full_paths["case2"]
    coarse = subsample(path, 9)
    fast = robot.inverse_kinematics(coarse)
    ipopt = robot.inverse_kinematics(coarse, solver="ipopt")
    assert ipopt.success, ipopt.message
    assert_close(fast.samples.phi, ipopt.samples.phi, rtol=0, atol=1e-9, what="Phi")


def test_fast_solver_matches_on_the_full_path_where_reference_is_sampled(robot, full_paths):
    path, result = full_paths["case1"]
    block = paths.TipPath(
        "block", path.t[1000:1010], path.position[1000:1010], path.velocity[1000:1010], path.acceleration[1000:1010]
    )
    reference = robot.inverse_kinematics(block, solver="slsqp", initial_guess=result.q[999])
    assert_close(result.samples.phi[1000:1010], reference.samples.phi, rtol=0, atol=1e-9, what="Phi")


def test_per_sample_record_shapes_and_labels(full_paths):
    path, result = full_paths["case2"]
    n, samples = len(path), full_paths["case2"][1].samples
    assert samples.success.shape == samples.residual.shape == samples.phi.shape == samples.iterations.shape == (n,)
    k = samples.active.shape[1]
    assert samples.active.shape == samples.inequality_multipliers.shape == (n, k)
    assert len(samples.constraint_labels) == k == 16
    assert samples.constraint_labels[0] == "s1 >= min" and samples.constraint_labels[13] == "psi3 <= max"
    assert samples.constraint_labels[14].startswith("module 1: s + 2d > p")
    assert samples.active_bounds.shape == (n, 14) and samples.active_assembly.shape == (n, 2)
    assert samples.multipliers.shape == (n, 3)
    assert np.isnan(samples.orientation_error).all()
    assert result.solver == "fast" and result.rates == "exact" and result.task == "position"
    assert result.wall_time_s > 0 and result.message.startswith("all")
    assert set(samples.method) == {"newton"}
    with pytest.raises(AttributeError):
        result.q = result.q  # type: ignore[misc]


def test_solver_registry_names():
    assert solver_names() == ["fast", "ipopt", "reference", "slsqp"]


def test_robot_method_delegates(robot):
    path = paths.case2(0.05)
    a = robot.inverse_kinematics(path)
    b = inverse_kinematics(robot, path)
    assert_close(a.q, b.q, rtol=0, atol=0)


def test_custom_margin_is_respected(robot):
    path = paths.waypoints([0.0, 1.0], [(0.0, 0.0, 0.66), (0.0, 0.0, 0.55)], dt=0.02, blend="quintic")
    result = robot.inverse_kinematics(path, margin=0.02)
    assert result.success
    assert robot.is_assemblable(result.q, margin=0.02 - 1e-12).all()
    assert result.samples.active_assembly.any()


def test_results_do_not_depend_on_the_initial_guess_near_home(robot):
    path = paths.case2(0.05)
    a = robot.inverse_kinematics(path)
    b = robot.inverse_kinematics(path, initial_guess=robot.parameters.home + 0.005)
    assert_close(a.q, b.q, rtol=0, atol=1e-9)


def test_vgtarm_exports():
    assert hasattr(vgtarm.Robot, "inverse_kinematics")


def test_result_arrays_are_read_only(full_paths):
    _, result = full_paths["case2"]
    for array in (result.q, result.qd, result.qdd, result.samples.phi, result.samples.active):
        with pytest.raises(ValueError, match="read-only"):
            array[0] = 0


def test_samples_the_fast_solver_cannot_verify_are_re_solved_by_the_reference(robot):
    """With one Newton step allowed, most samples fail; the reference re-solves them and says so."""
    path = paths.case2(0.1)
    normal = robot.inverse_kinematics(path)
    starved = robot.inverse_kinematics(path, max_iterations=1)
    assert starved.success, starved.message
    fallback = starved.samples.method == "slsqp (fallback)"
    assert fallback.any() and (starved.samples.method[~fallback] == "newton").all()
    assert_close(starved.samples.phi, normal.samples.phi, rtol=0, atol=1e-9)


def test_without_fallback_unsolved_samples_are_reported_not_hidden(robot):
    path = paths.case2(0.1)
    result = robot.inverse_kinematics(path, max_iterations=1, fallback=False)
    failed = ~result.samples.success
    assert failed.any() and not result.success
    assert "failed the optimality check" in result.message
    assert (result.samples.method[failed] == "closest point (failed)").all()
    assert result.samples.residual.max() <= 1e-9  # still on the path: the closest feasible pose reaches it
