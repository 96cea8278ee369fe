"""Inverse kinematics of a robot whose tip moves in a plane or a line (issue 27, item 1).

The planar module's tip Jacobian has rank 2: its task is the tip's two coordinates in its plane,
with the third freedom spent on eq. 12. The answers are checked against things independent of the
reduced task's code: IPOPT on the task written symbolically, a multistart SLSQP on the same
problem written here from the robot's forward kinematics alone, the forward kinematics of the
answer, the time derivatives of the answer, and the geometry of the placed case paths.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import minimize

import vgtarm
from vgtarm import paths
from vgtarm.experiment.cases import PAPER_HOME_TIP, PathPlacement, case_path, case_study, path_placement
from vgtarm.ik import SOLVERS
from vgtarm.ik.options import IKOptions
from vgtarm.ik.problem import IKProblem
from vgtarm.ik.solve import _task
from vgtarm.ik.taskspace import TaskSpace, canonical, task_space

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.fixture(scope="module")
def planar() -> vgtarm.Robot:
    return vgtarm.load_robot(EXAMPLES / "planar_module.toml")


@pytest.fixture(scope="module")
def wave(planar) -> paths.TipPath:
    """A smooth in-plane closed curve through the home tip, with analytic derivatives (1 s, 2 ms)."""
    tip = planar.tip_position(planar.parameters.home)
    t = np.linspace(0.0, 1.0, 501)
    w = 2 * np.pi
    zero = np.zeros_like(t)
    position = tip + np.column_stack([zero, 0.02 * np.sin(w * t), 0.01 * (1 - np.cos(2 * w * t))])
    velocity = np.column_stack([zero, 0.02 * w * np.cos(w * t), 0.02 * w * np.sin(2 * w * t)])
    acceleration = np.column_stack([zero, -0.02 * w**2 * np.sin(w * t), 0.04 * w**2 * np.cos(2 * w * t)])
    jerk = np.column_stack([zero, -0.02 * w**3 * np.cos(w * t), -0.08 * w**3 * np.sin(2 * w * t)])
    return paths.TipPath("wave", t, position, velocity, acceleration, jerk)


def test_the_planar_module_tracks_its_plane_and_the_3d_robots_their_space(planar):
    space = task_space(planar, planar.parameters.home)
    assert space is not None and space.rank == 2
    np.testing.assert_array_equal(space.directions, [[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])  # exactly (u2, u3)
    np.testing.assert_array_equal(space.normal(), [1.0, 0.0, 0.0])
    assert space.label == "tip (u2, u3) in its plane"
    # the plane holds every tip the robot reaches (forward kinematics at random assemblable poses)
    rng = np.random.default_rng(4)
    p = planar.parameters
    q = p.lower + (p.upper - p.lower) * rng.uniform(0.1, 0.9, (200, 3))
    q = q[planar.is_assemblable(q, 1e-3)]
    assert len(q) > 50 and space.distance(planar.tip_position(q)).max() <= 1e-15
    for robot in (vgtarm.load_robot(), vgtarm.load_robot(EXAMPLES / "paper_robot.toml")):
        assert task_space(robot, robot.parameters.home) is None  # rank 3: the full task, unchanged


def test_canonical_directions_span_the_same_subspace_and_prefer_the_base_axes():
    rng = np.random.default_rng(1)
    for angle in (0.0, 30.0, 90.0, 137.0):
        a = np.radians(angle)
        plane = np.array([[np.cos(a), np.sin(a), 0.0], [0.0, 0.0, 1.0]])  # a module turned by `angle`
        mixed = np.linalg.qr(plane.T @ np.linalg.qr(rng.normal(size=(2, 2)))[0])[0].T  # any basis of it
        rows = canonical(mixed)
        np.testing.assert_allclose(rows @ rows.T, np.eye(2), atol=1e-15)
        np.testing.assert_allclose(rows.T @ rows, plane.T @ plane, atol=1e-14)  # the same plane
        assert [0.0, 0.0, 1.0] in rows.tolist()  # the vertical axis is one of them, exactly
    line = canonical(np.array([[0.6, 0.0, -0.8]]))
    np.testing.assert_allclose(line, [[-0.6, 0.0, 0.8]], atol=1e-15)  # its largest entry made positive


def _multistart_slsqp(robot: vgtarm.Robot, target: np.ndarray, E: np.ndarray, margin: float, seed: int) -> np.ndarray:
    """The reduced problem written from scratch: min Phi s.t. E (P(q) - target) = 0, the limits and the
    triangle rows with the margin, by SLSQP from 8 seeded starts (numerical derivatives of the tip)."""
    p = robot.parameters
    n = p.lower.shape[0]
    centre, width = (p.lower + p.upper) / 2, p.upper - p.lower
    G, h = p.margin_form()
    rng = np.random.default_rng(seed)
    best, best_cost = None, np.inf
    for start in centre + width * rng.uniform(-0.3, 0.3, (8, n)):
        result = minimize(
            lambda q: float(np.sum(((q - centre) / width) ** 2)) / n,
            start,
            method="SLSQP",
            bounds=list(zip(p.lower, p.upper, strict=True)),
            constraints=[
                {"type": "eq", "fun": lambda q: E @ (robot.tip_position(q) - target)},
                {"type": "ineq", "fun": lambda q: G @ q + h - margin},
            ],
            options={"ftol": 1e-15, "maxiter": 500},
        )
        if result.success and result.fun < best_cost:
            best, best_cost = result.x, result.fun
    assert best is not None
    return best


def _every(path: paths.TipPath, k: int) -> paths.TipPath:
    jerk = None if path.jerk is None else path.jerk[::k]
    return paths.TipPath(path.name, path.t[::k], path.position[::k], path.velocity[::k], path.acceleration[::k], jerk)


def test_fast_ipopt_and_an_independent_multistart_slsqp_agree(planar, wave):
    fast = planar.inverse_kinematics(wave)
    coarse = _every(wave, 20)  # the same targets, fewer of them for the per-sample reference solvers
    ipopt = planar.inverse_kinematics(coarse, solver="ipopt")
    slsqp = planar.inverse_kinematics(coarse, solver="slsqp")
    for result, path in ((fast, wave), (ipopt, coarse), (slsqp, coarse)):
        assert result.success, result.message
        assert result.task_space == "tip (u2, u3) in its plane"
        assert result.samples.multipliers.shape == (len(path), 2)
        # forward kinematics of the answer lands on the target, in all three coordinates
        np.testing.assert_allclose(planar.tip_position(result.q), path.position, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast.q[::20], ipopt.q, rtol=0, atol=1e-10)
    np.testing.assert_allclose(fast.q[::20], slsqp.q, rtol=0, atol=1e-7)  # SLSQP stops at its ftol
    E = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    for i in (0, len(wave) // 3, len(wave) - 1):
        q = _multistart_slsqp(planar, wave.position[i], E, fast.margin, seed=i)
        np.testing.assert_allclose(fast.q[i], q, rtol=0, atol=1e-6)


def test_exact_rates_differentiate_the_optimum(planar, wave):
    result = planar.inverse_kinematics(wave)
    assert not result.samples.active.any()
    dt = wave.dt
    inner = slice(2, -2)
    # first and second time derivatives of the solved q (central differences, error O(dt^2))
    np.testing.assert_allclose(result.qd[inner], np.gradient(result.q, dt, axis=0)[inner], rtol=0, atol=2e-5)
    np.testing.assert_allclose(result.qdd[inner], np.gradient(result.qd, dt, axis=0)[inner], rtol=0, atol=5e-3)
    # the tip's velocity and acceleration: J qd = xd and J qdd + (dJ/dq qd) qd = xdd
    J = planar.tip_jacobian(result.q)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", J, result.qd), wave.velocity, rtol=0, atol=1e-13)
    h = 1e-6
    Jdot = (planar.tip_jacobian(result.q + h * result.qd) - planar.tip_jacobian(result.q - h * result.qd)) / (2 * h)
    acceleration = np.einsum("nij,nj->ni", J, result.qdd) + np.einsum("nij,nj->ni", Jdot, result.qd)
    np.testing.assert_allclose(acceleration, wave.acceleration, rtol=0, atol=1e-8)


def test_a_line_task_solved_by_every_solver_agrees(planar):
    """A task of one row (rank 1): only the tip's height, the two other freedoms on eq. 12."""
    tip = planar.tip_position(planar.parameters.home)
    path = paths.waypoints([0.0, 1.0], [tip, tip + [0.0, 0.0, 0.02]], 0.05, blend="quintic", name="lift")
    space = TaskSpace(np.array([[0.0, 0.0, 1.0]]), tip, "tip u3 along its line")
    problem = IKProblem.from_parameters(planar.parameters)
    options = IKOptions.from_keywords({}, planar.n_joints)
    answers = {}
    for name in ("fast", "ipopt"):
        task = _task(planar, path, None, None, space)
        state = SOLVERS[name](problem, task, planar.parameters.home, options).state
        assert state.converged.all(), name
        answers[name] = state.q.copy()
        np.testing.assert_allclose(planar.tip_position(state.q)[:, 2], path.position[:, 2], rtol=0, atol=1e-12)
    np.testing.assert_allclose(answers["fast"], answers["ipopt"], rtol=0, atol=1e-9)


def test_the_effort_criterion_on_the_plane_agrees_with_ipopt(planar, wave):
    short = _every(wave, 25)
    fast = planar.inverse_kinematics(short, criterion="effort", tool_force=10.0)
    ipopt = planar.inverse_kinematics(short, criterion="effort", tool_force=10.0, solver="ipopt")
    assert fast.success and ipopt.success, (fast.message, ipopt.message)
    np.testing.assert_allclose(fast.q, ipopt.q, rtol=0, atol=1e-9)


def test_a_point_off_the_plane_or_a_pose_is_refused_in_one_line(planar, wave):
    off = paths.TipPath("off", wave.t, wave.position + [0.003, 0.0, 0.0], wave.velocity, wave.acceleration)
    with pytest.raises(vgtarm.errors.UnreachableError, match=r"0\.003 m off the plane") as caught:
        planar.inverse_kinematics(off)
    assert "\n" not in str(caught.value) and "tip (u2, u3)" in str(caught.value)
    with pytest.raises(vgtarm.errors.InputError, match="leave pose out"):
        planar.inverse_kinematics(wave, pose="hold")
    point = vgtarm.ik.solve_point(planar, wave.position[0] + [0.003, 0.0, 0.0])
    assert not point.success and abs(point.residual - 0.003) < 1e-9  # the closest: the point's foot in the plane


def test_case_paths_are_turned_into_the_plane_with_the_same_timing(planar):
    placement = path_placement(planar)
    assert placement is not None and placement.space is not None
    assert placement.metadata()["ik_task"] == "tip (u2, u3) in its plane"
    home = planar.tip_position(planar.parameters.home)
    for number in (1, 2):
        original, placed = case_study(number).path(1e-3), case_path(planar, number)
        np.testing.assert_array_equal(placed.t, original.t)
        assert np.abs(placed.position[:, 0] - home[0]).max() == 0.0  # in the plane x = 0, exactly
        # the velocity is that of the placed points (one linear map for both): central differences miss it
        # by no more than they miss the original path's, times the scale
        for new, old in ((placed.position, original.position), (placed.velocity, original.velocity)):
            rate = placed.velocity if new is placed.position else placed.acceleration
            old_rate = original.velocity if old is original.position else original.acceleration
            miss = np.linalg.norm(np.gradient(new, 1e-3, axis=0) - rate, axis=1)
            old_miss = np.linalg.norm(np.gradient(old, 1e-3, axis=0) - old_rate, axis=1)
            assert (miss <= placement.scale * old_miss + 1e-12).all()
    # case 2 is planar (three corners): turned rigidly, its speed is the scaled speed, its corners as far apart
    original, placed = case_study(2).path(1e-3), case_path(planar, 2)
    speed = np.linalg.norm(original.velocity, axis=1) * placement.scale
    np.testing.assert_allclose(np.linalg.norm(placed.velocity, axis=1), speed, rtol=0, atol=1e-15)
    corners = np.array([[0.03, -0.04, 0.64], [-0.04, 0.03, 0.68], [0.04, 0.05, 0.62]])
    k = [0, len(placed) // 2, len(placed) - 1]
    gaps = np.linalg.norm(np.diff(corners, axis=0), axis=1) * placement.scale
    np.testing.assert_allclose(np.linalg.norm(np.diff(placed.position[k], axis=0), axis=1), gaps, atol=1e-15)
    # case 1's circle (horizontal, radius 6 cm) becomes a vertical circle of radius 6 cm times the scale
    placed = case_path(planar, 1)
    radius = np.linalg.norm(placed.position[:, 1:] - home[1:], axis=1)
    np.testing.assert_allclose(radius, 0.06 * placement.scale, rtol=1e-12)
    assert path_placement(vgtarm.load_robot()) is None and tuple(case_study(1).path().position[0]) == (
        PAPER_HOME_TIP[0],
        PAPER_HOME_TIP[1] + 0.06,
        PAPER_HOME_TIP[2],
    )


def test_simulate_on_a_path_file_in_the_plane_records_the_task_and_refuses_one_off_it(planar, tmp_path, capsys):
    from vgtarm.app.cli import main

    config = str(EXAMPLES / "planar_module.toml")
    rows = ["t,x,y,z"] + [f"{0.001 * k:g},0,{0.0001 * k:g},{0.33 + 0.00005 * k:g}" for k in range(51)]
    (tmp_path / "in.csv").write_text("\n".join(rows) + "\n")
    out = tmp_path / "run"
    assert main(["simulate", "--path", str(tmp_path / "in.csv"), "--config", config, "--out", str(out), "-q"]) == 0
    assert "tip (u2, u3) in its plane" in capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert summary["ik_task"] == "tip (u2, u3) in its plane" and summary["success"]
    rows[2] = "0.001,0.01,0.0001,0.33005"  # one point 1 cm off the plane x = 0
    (tmp_path / "off.csv").write_text("\n".join(rows) + "\n")
    assert main(["simulate", "--path", str(tmp_path / "off.csv"), "--config", config, "-q"]) == 1
    err = capsys.readouterr().err
    assert "0.01 m off the plane" in err and err.count("\n") == 1


def test_on_a_line_a_case_path_is_projected_on_it():
    line = TaskSpace(np.array([[0.0, 0.0, 1.0]]), np.array([0.1, 0.2, 0.5]), "tip u3 along its line")
    placement = PathPlacement((0.1, 0.2, 0.5), 0.5, 0.55, line)
    original = case_study(2).path(1e-3)
    placed = placement.apply(original)
    np.testing.assert_array_equal(placed.position[:, :2], np.broadcast_to([0.1, 0.2], (len(placed), 2)))
    np.testing.assert_allclose(placed.position[:, 2], 0.5 + 0.5 * (original.position[:, 2] - 0.66), atol=1e-15)
    np.testing.assert_allclose(placed.acceleration[:, 2], 0.5 * original.acceleration[:, 2], atol=1e-15)
    metadata = placement.metadata()
    assert metadata["ik_task"] == "tip u3 along its line" and "path_plane_normal" not in metadata


@pytest.mark.parametrize("angle", [30.0, 90.0])
def test_a_module_in_a_turned_plane_gets_its_plane_from_the_jacobian(angle, tmp_path):
    """The plane found from the Jacobians is the one the module's description gives (its h axis
    ``(-sin a, cos a, 0)`` and the vertical), and the IK and the case paths follow it. The model is
    interpreted here: a new plane angle is a new structure, whose compilation would take a while."""
    from vgtarm.model.compiled import get_backend
    from vgtarm.model.robot import Robot, definition_of
    from vgtarm.model.stack import load_stack

    text = (EXAMPLES / "planar_module.toml").read_text().replace("plane = 0.0 ", f"plane = {angle} ")
    (tmp_path / "turned.toml").write_text(text)
    stack = load_stack(tmp_path / "turned.toml")
    robot = Robot(stack, get_backend("interpreted", definition_of(stack)))
    space = task_space(robot, stack.home)
    a = np.radians(angle)
    described = np.array([[-np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    assert space is not None
    np.testing.assert_allclose(space.directions.T @ space.directions, described.T @ described, atol=1e-14)
    assert space.label == (
        "tip (u1, u3) in its plane" if angle == 90.0 else "tip along (-0.5, 0.866, 0) and u3 in its plane"
    )
    path = _every(case_path(robot, 2), 400)  # 11 samples of case 2, turned into the plane
    assert space.distance(path.position).max() <= 1e-15
    result = robot.inverse_kinematics(path)
    assert result.success and result.task_space == space.label
    np.testing.assert_allclose(robot.tip_position(result.q), path.position, rtol=0, atol=1e-12)
