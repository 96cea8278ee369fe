"""The effort criterion of the inverse kinematics (issue 22): optimum, exact rates, forces, options."""

from __future__ import annotations

import re

import numpy as np
import pytest

from vgtarm import paths
from vgtarm.errors import InputError
from vgtarm.ik.effort import expected_tool_force, reference_efforts
from vgtarm.ik.options import IKOptions

#: Cutting force of the paper's case 2 (N).
F0 = 20.0


def leg_forces(robot, path, q, force=F0):
    """Static leg forces ``(N, 6)`` that hold ``q`` against gravity and the expected tool force."""
    f, _, _ = expected_tool_force(path, force, IKOptions().tool_force_speed)
    zero = np.zeros_like(q)
    return robot.inverse_dynamics(q, zero, zero, f)[:, :6]


def test_static_efforts_are_the_dynamics_at_rest(robot):
    """``ik_effort_static``'s ``tau`` (from the potential energy) equals ``M 0 + C(q, 0) - J_P^T f``."""
    rng = np.random.default_rng(0)
    home = robot.parameters.home
    q = home + rng.uniform(-0.02, 0.02, size=(20, 7))
    f = rng.uniform(-30, 30, size=(20, 3))
    scale = 1.0 / reference_efforts(robot)
    out = robot.evaluate("ik_effort_static", {"q": q, "f": f, "s": scale}, 20)
    zero = np.zeros_like(q)
    expected = robot.inverse_dynamics(q, zero, zero, f)
    np.testing.assert_allclose(out["tau"], expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out["phi"][:, 0], ((expected * scale) ** 2).sum(axis=1) / 7, rtol=1e-14)


def test_expected_tool_force_derivatives():
    """``f, fd, fdd`` of the expected cutting force agree with central differences along case 2."""
    path = paths.case2(dt=1e-4)
    f, fd, fdd = expected_tool_force(path, F0, 0.01)
    h = path.dt
    inside = slice(5000, 15000)  # away from the corners' jerk jump
    num_fd = (f[2:] - f[:-2]) / (2 * h)
    num_fdd = (f[2:] - 2 * f[1:-1] + f[:-2]) / h**2
    np.testing.assert_allclose(fd[1:-1][inside], num_fd[inside], rtol=0, atol=1e-5)
    np.testing.assert_allclose(fdd[1:-1][inside], num_fdd[inside], rtol=0, atol=1e-2)
    speed = np.linalg.norm(path.velocity, axis=1)
    moving = speed > 1e-4
    sigma = speed[moving] / np.hypot(speed[moving], 0.01)
    np.testing.assert_allclose(np.linalg.norm(f[moving], axis=1), F0 * sigma**3, rtol=1e-12)
    unit = path.velocity[moving] / speed[moving, None]
    np.testing.assert_allclose(f[moving] / np.linalg.norm(f[moving], axis=1)[:, None], -unit, rtol=0, atol=1e-12)


def test_the_expected_force_and_the_reference_start_at_rest(robot):
    """From rest the expected force grows with the cube of the speed (zero slope and curvature), so the
    effort optimum does not move while the path rests: the reference's joint velocity at t = 0 is zero,
    as the robot's; the force model of before (``-F0 v / sqrt(|v|^2 + v_s^2)``, slope ``-F0 a / v_s``)
    moved it at up to 45 mm/s there."""
    path = paths.case2()
    f, fd, fdd = expected_tool_force(path, F0, 0.03)
    assert np.abs(f[0]).max() == 0.0 and np.abs(fd[0]).max() == 0.0 and np.abs(fdd[0]).max() == 0.0
    size = np.linalg.norm(f, axis=1)  # from rest the tip speed grows as a t: |f| as t^3
    np.testing.assert_allclose(size[2:8:2] / size[1:4], 8.0, rtol=1e-2)  # the model of before: 2
    effort = robot.inverse_kinematics(path, criterion="effort", tool_force=F0)
    assert effort.success
    assert np.abs(effort.qd[0]).max() < 1e-12
    assert np.abs(effort.qd[50]).max() > 1e-4  # and then it moves


@pytest.fixture(scope="module")
def case2_coarse():
    return paths.case2(dt=0.25)


def test_optimum_equals_ipopt(robot, case2_coarse):
    """The fast solver's KKT point has IPOPT's cost (the same nonlinear program, written symbolically)."""
    fast = robot.inverse_kinematics(case2_coarse, criterion="effort", tool_force=F0)
    ipopt = robot.inverse_kinematics(case2_coarse, criterion="effort", tool_force=F0, solver="ipopt")
    assert fast.success and ipopt.success
    np.testing.assert_allclose(fast.samples.phi, ipopt.samples.phi, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fast.q, ipopt.q, rtol=0, atol=1e-6)


def test_optimum_beats_every_start(robot, case2_coarse):
    """Multi-start: IPOPT started from the eq. 12 optimum and from perturbed poses finds no lower cost."""
    from vgtarm.ik.problem import IKProblem
    from vgtarm.ik.reference import build_ipopt

    fast = robot.inverse_kinematics(case2_coarse, criterion="effort", tool_force=F0)
    plain = robot.inverse_kinematics(case2_coarse)
    options = IKOptions(criterion="effort", tool_force=F0)
    problem = IKProblem.from_parameters(robot.parameters, options.margin, options.joint_limit_weight)
    solver = build_ipopt(problem, "position", options, robot.definition, effort=True)
    f, _, _ = expected_tool_force(case2_coarse, F0, options.tool_force_speed)
    scale = 1.0 / reference_efforts(robot)
    lbg = np.concatenate([np.zeros(3), np.full(problem.n_triangle, problem.margin)])
    ubg = np.concatenate([np.zeros(3), np.full(problem.n_triangle, np.inf)])
    rng = np.random.default_rng(1)
    for i in range(0, len(case2_coarse), 3):
        p = np.concatenate([case2_coarse.position[i], f[i], scale, robot.parameter_vector])
        starts = [plain.q[i]] + [plain.q[i] + rng.uniform(-0.02, 0.02, 7) for _ in range(3)]
        for start in starts:
            out = solver(x0=start, p=p, lbx=problem.lower, ubx=problem.upper, lbg=lbg, ubg=ubg)
            if solver.stats()["success"]:
                assert float(out["f"]) >= fast.samples.phi[i] - 1e-9


def test_static_forces_drop_on_case2(robot):
    """On case 2 with the cutting force the effort criterion lowers the RMS and the peak holding leg force."""
    path = paths.case2()
    plain = robot.inverse_kinematics(path)
    effort = robot.inverse_kinematics(path, criterion="effort", tool_force=F0)
    assert effort.success
    before, after = leg_forces(robot, path, plain.q), leg_forces(robot, path, effort.q)
    rms_before, rms_after = np.sqrt(np.mean(before**2)), np.sqrt(np.mean(after**2))
    assert rms_after < 0.9 * rms_before  # measured: 23.47 N -> 20.60 N (-12.2 %)
    assert np.abs(after).max() < 0.85 * np.abs(before).max()  # measured: 60.1 N -> 49.3 N


@pytest.mark.parametrize("case", [1, 2])
def test_exact_rates(robot, case):
    """``J_P qd = xd``, ``J_P qdd + Jdot_P qd = xdd``, and the rates agree with finite differences of ``q``."""
    path = paths.case1() if case == 1 else paths.case2()
    ref = robot.inverse_kinematics(path, criterion="effort", tool_force=0.0 if case == 1 else F0)
    assert ref.success
    J = robot.tip_jacobian(ref.q)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", J, ref.qd), path.velocity, rtol=0, atol=1e-13)
    bias = robot.bias_accelerations(ref.q, ref.qd).tip
    # qdd reaches a few m/s^2 where the expected tool force turns at case 2's corner: 1e-11 relative
    atol = 1e-11 * np.abs(ref.qdd).max()
    np.testing.assert_allclose(np.einsum("nij,nj->ni", J, ref.qdd) + bias, path.acceleration, rtol=0, atol=atol)
    dt = path.dt
    q = ref.q
    num_qd = (q[2:] - q[:-2]) / (2 * dt)
    num_qdd = (q[2:] - 2 * q[1:-1] + q[:-2]) / dt**2
    # case 2: away from the corners, where the expected tool force turns within a few ms (below its
    # smoothing speed, 3 cm/s; there the differences' own dt^2 error is larger: measured, it falls
    # 4x per halving of dt, 1.6e-5 -> 4.0e-6 -> 1.0e-6 relative above 2 cm/s)
    keep = np.ones(len(path) - 2, dtype=bool)
    if case == 2:
        keep &= np.linalg.norm(path.velocity[1:-1], axis=1) > 0.03
    scale_qd, scale_qdd = np.abs(ref.qd).max(), np.abs(ref.qdd).max()
    assert np.abs(num_qd - ref.qd[1:-1])[keep].max() <= 1e-5 * scale_qd
    assert np.abs(num_qdd - ref.qdd[1:-1])[keep].max() <= 1e-3 * scale_qdd


def test_default_criterion_unchanged(robot):
    """The default is eq. 12: the same arrays bit for bit as criterion='joint_limits'."""
    path = paths.case2(dt=0.01)
    a = robot.inverse_kinematics(path)
    b = robot.inverse_kinematics(path, criterion="joint_limits")
    assert np.array_equal(a.q, b.q) and np.array_equal(a.qd, b.qd) and np.array_equal(a.qdd, b.qdd)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"criterion": "force"}, "criterion = 'force': expected one of ['joint_limits', 'effort']"),
        ({"tool_force": 20.0}, "tool_force applies to criterion='effort' only"),
        ({"criterion": "effort", "tool_force": -1.0}, "tool_force = -1.0: expected a finite number >= 0 (N)"),
        ({"criterion": "effort", "joint_limit_weight": 0.0}, "joint_limit_weight = 0.0: expected a finite number > 0"),
        ({"criterion": "effort", "pose": "hold"}, "supports the tip, axis and entry-point tasks, not the full pose"),
    ],
)
def test_bad_options(robot, options, message):
    with pytest.raises(InputError, match=re.escape(message)):
        robot.inverse_kinematics(paths.case2(dt=0.5), **options)


def test_path_without_jerk_refused(robot):
    path = paths.case2(dt=0.5)
    bare = paths.TipPath(path.name, path.t, path.position, path.velocity, path.acceleration)
    with pytest.raises(InputError, match="has no jerk"):
        robot.inverse_kinematics(bare, criterion="effort", tool_force=F0)


def test_cli_effort_criterion(tmp_path, capsys):
    """`vgtarm ik --criterion effort --tool-force 20` writes the reference; `--tool-force` alone is refused."""
    from vgtarm.app.cli.command import main

    out = tmp_path / "ref.csv"
    assert (
        main(["ik", "--case", "2", "--dt", "0.05", "--criterion", "effort", "--tool-force", "20", "-o", str(out)]) == 0
    )
    assert out.is_file()
    assert main(["ik", "--case", "2", "--dt", "0.05", "--tool-force", "20"]) != 0
    assert "tool_force applies to criterion='effort' only" in capsys.readouterr().err
