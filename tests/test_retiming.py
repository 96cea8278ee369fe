"""Time-optimal retiming (vgtarm.retiming): against toppra 0.6.10 without friction (same grid,
geometry and limits), toppra's first-order profile against the friction it cannot hold, the
force-speed lines, a single joint whose optimum is known in closed form, the retimed reference's
rates against its positions and a closed-loop run on it, and the refusals.

The limits of the comparisons: every leg 60 N and 0.05 m/s (the issue's), the twist 5 N m and
3 rad/s: on case 1 the twist does not move and on case 2 it moves little, so the legs' limits make
the timing, with a force and a speed limit both reached (asserted; measured at 300 points without
friction: on case 1 the speeds of s1, v1, s2, v2, p2 bound most of the path and v1's force a few
points, on case 2 the speeds of s1, p1, s2, p2 and the forces of s1, v1, p2)."""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid
from scipy.optimize import brentq

import vgtarm
from vgtarm import retiming
from vgtarm.control import ComputedForceControl
from vgtarm.errors import InputError
from vgtarm.model.actuators import Actuator, Actuators

ta = pytest.importorskip("toppra")
from benchmarks.bench_retime import limits, toppra_problem  # noqa: E402  (the benchmark's problem and limits)

logging.getLogger("toppra").setLevel(logging.WARNING)

GRID = 300
#: A joint force within its bound at a grid point: the solver's rounding (N, N m).
FORCE_TOLERANCE = 1e-7


@pytest.fixture(scope="module")
def frictionless(robot: vgtarm.Robot) -> vgtarm.Robot:
    return robot.with_parameters(dataclasses.replace(robot.parameters, viscous=(0.0,) * robot.n_joints))


@pytest.fixture(scope="module")
def paths(robot: vgtarm.Robot) -> dict[str, vgtarm.IKResult]:
    return {name: vgtarm.inverse_kinematics(robot, getattr(vgtarm.paths, name)()) for name in ("case1", "case2")}


def _toppra(robot: vgtarm.Robot, reference, actuators: Actuators, grid: int):
    """toppra's TOPP-RA on the same geometry, grid and box limits (``robot``: its dynamics)."""
    problem, geometry = toppra_problem(robot, reference, actuators, grid)
    trajectory = problem.compute_trajectory(0, 0)
    assert trajectory is not None
    return trajectory, problem.problem_data, geometry


@pytest.mark.parametrize("case", ["case1", "case2"])
def test_without_friction_the_duration_is_toppras(frictionless, paths, case):
    actuators = limits(frictionless)
    trajectory, _, _ = _toppra(frictionless, paths[case], actuators, GRID)
    ours = retiming.retime(frictionless, paths[case], actuators=actuators, grid=GRID, scheme="departure", refine=0)
    assert ours.duration == pytest.approx(trajectory.duration, rel=1e-3)
    assert ours.duration < paths[case].t[-1] - paths[case].t[0]
    # both kinds of limit are reached: a joint speed and a joint force (at the grid points)
    y = np.sqrt(ours.x)
    assert (y >= ours.profile.speed * (1 - 1e-9)).any(), "no speed limit reached"
    motion = ours.collocated()
    F = frictionless.inverse_dynamics(motion.q, motion.qd, motion.qdd)
    share = actuators.utilisation(F, motion.qd).max(axis=0)
    assert share.max() == pytest.approx(1.0, abs=1e-9), f"no force limit reached: {share}"


def _grid_motion(geometry: retiming.Geometry, data) -> retiming.GridMotion:
    """toppra's profile at its grid points, each with the ``sddot`` of the interval after it."""
    sd = np.asarray(data.sd_vec, dtype=float)
    return retiming.collocated(
        geometry, np.asarray(data.gridpoints, dtype=float), sd * sd, np.append(data.sdd_vec, 0.0)
    )


def test_with_friction_toppras_profile_exceeds_the_force_and_ours_does_not(robot, frictionless, paths):
    """toppra cannot hold the legs' viscous friction (200 N s/m, first order in sdot): its profile,
    checked with the friction, asks more than 60 N somewhere; ours, with the friction exact, never."""
    actuators = limits(robot)
    _, data, geometry = _toppra(frictionless, paths["case1"], actuators, GRID)
    theirs = retiming.force_excess(robot, _grid_motion(geometry, data), actuators)
    assert theirs.max() > 1.0
    for scheme in retiming.SCHEMES:
        ours = retiming.retime(robot, paths["case1"], actuators=actuators, grid=GRID, scheme=scheme)
        assert retiming.force_excess(robot, ours.collocated(), actuators).max() <= FORCE_TOLERANCE
        # holding the friction costs time, and ignoring it gives toppra's profile
        ignored = retiming.retime(robot, paths["case1"], actuators=actuators, grid=GRID, scheme=scheme, friction=False)
        assert ours.duration > ignored.duration
    ignored = retiming.retime(
        robot, paths["case1"], actuators=actuators, grid=GRID, scheme="departure", friction=False, refine=0
    )
    np.testing.assert_allclose(np.sqrt(ignored.x), data.sd_vec, atol=1e-5)


@pytest.mark.parametrize("case", ["case1", "case2"])
def test_with_force_speed_lines_no_force_exceeds_its_bound(robot, paths, case):
    lines = limits(robot, line=True)
    ours = retiming.retime(robot, paths[case], actuators=lines, grid=GRID, tool_force=5.0)
    assert retiming.force_excess(robot, ours.collocated(), lines, tool_force=5.0).max() <= FORCE_TOLERANCE
    # the lines only take force away: slower than with the box
    box = retiming.retime(robot, paths[case], actuators=limits(robot), grid=GRID, tool_force=5.0)
    assert ours.duration > box.duration


def _one_joint(points: int, m: float, F0: float, c: float, L: float) -> retiming.PathDynamics:
    """A mass ``m`` (kg) on a straight line of length ``L`` (m), ``s`` its position (``q = s``),
    against a constant force ``F0`` (N) and viscous friction ``c`` (N s/m)."""
    s = np.linspace(0.0, L, points)
    one = np.ones((points, 1))
    return retiming.PathDynamics(s=s, q=s[:, None], qs=one, qss=0 * one, a=m * one, b=0 * one, c=F0 * one, d=c * one)


@pytest.mark.parametrize("scheme", retiming.SCHEMES)
def test_one_joint_against_a_force_on_its_force_speed_line_is_bang_bang(scheme):
    """A mass m moved a distance L from rest to rest against a constant force F0 and viscous
    friction c by a motor on its force-speed line (stall force F_s, no-load speed v_max; braking
    keeps F_s). The fastest motion is bang-bang: full force, then full braking. Accelerating,
    m dv/dt = F_s (1 - v/v_max) - c v - F0 = a0 - k v (a0 = F_s - F0, k = F_s/v_max + c), so
    t_a(v) = -(m/k) ln(1 - k v/a0) and the distance x_a(v) = int m v dv/(a0 - k v)
    = (m/k) (-v - (a0/k) ln(1 - k v/a0)); braking, m dv/dt = -(b0 + c v) (b0 = F_s + F0), so from
    v to rest t_b(v) = (m/c) ln(1 + c v/b0) and x_b(v) = (m/c) (v - (b0/c) ln(1 + c v/b0)). The
    switch speed v* solves x_a(v*) + x_b(v*) = L (one scalar root, below the final speed a0/k,
    itself below v_max: the speed limit never binds), and the duration is t_a(v*) + t_b(v*)."""
    m, F0, c, L, Fs, vmax = 2.0, 2.0, 5.0, 0.5, 10.0, 1.0
    a0, k, b0 = Fs - F0, Fs / vmax + c, Fs + F0

    def x_a(v: float) -> float:
        return m / k * (-v - a0 / k * np.log1p(-k * v / a0))

    def x_b(v: float) -> float:
        return m / c * (v - b0 / c * np.log1p(c * v / b0))

    v_switch = brentq(lambda v: x_a(v) + x_b(v) - L, 1e-9, a0 / k * (1 - 1e-12), xtol=1e-15)
    exact = -m / k * np.log1p(-k * v_switch / a0) + m / c * np.log1p(c * v_switch / b0)
    motor = Actuators(names=("x",), joints=(Actuator(force=Fs, speed=vmax, force_speed=True),))
    durations = [retiming.solve(_one_joint(n, m, F0, c, L), motor, scheme).duration for n in (500, 1000, 2000)]
    errors = np.abs(np.array(durations) / exact - 1)
    assert errors[-1] < 2e-3, (durations, exact)
    assert errors[0] > errors[1] > errors[2]  # converges with the grid
    profile = retiming.solve(_one_joint(2000, m, F0, c, L), motor, scheme)
    assert np.sqrt(profile.x).max() == pytest.approx(v_switch, rel=5e-3)


def test_the_retimed_reference_is_consistent_starts_and_ends_at_rest_and_simulates(robot, paths):
    ours = retiming.retime(robot, paths["case1"], actuators=limits(robot), grid=200, refine=0)
    dt = 1e-3
    ref = ours.reference(dt)
    assert isinstance(ref, vgtarm.JointReference)
    assert ref.t[-1] >= ours.duration > ref.t[-2]
    np.testing.assert_array_equal(ref.qd[[0, -1]], 0.0)
    assert np.abs(ref.qd[-1]).max() == 0.0 and np.abs(ref.q[-1] - paths["case1"].q[-1]).max() < 1e-12
    # the rates are those of q: fourth-order central differences of q and qd over five samples
    # within one grid interval (sddot is constant per interval and jumps between them, where a
    # difference is off by the jump), and the velocity integrates to q everywhere; q'' is linear
    # between the reference's samples (1 ms), the derivative of q' a quadratic: O(h^2) apart
    interval = np.searchsorted(ours.t, ref.t, side="right")
    inside = interval[:-4] == interval[4:]
    assert inside.mean() > 0.6
    for value, rate, tolerance in ((ref.q, ref.qd, 1e-7), (ref.qd, ref.qdd, 1e-5)):
        central = (value[:-4] - 8 * value[1:-3] + 8 * value[3:-1] - value[4:]) / (12 * dt)
        error = np.abs(central - rate[2:-2])[inside]
        assert error.max() < tolerance * np.abs(rate).max(), error.max() / np.abs(rate).max()
    q_of_qd = ref.q[0] + cumulative_trapezoid(ref.qd, ref.t, axis=0, initial=0.0)
    assert np.abs(q_of_qd - ref.q).max() < 1e-6  # m, rad; the legs travel ~0.1 m
    # a closed-loop run on it (its first second)
    run = vgtarm.simulate(robot, ref.head(1000), ComputedForceControl.with_gains(5000.0, 300.0))
    assert run.success


def test_the_figure_has_the_phase_plane_and_the_utilisation(robot, paths):
    ours = retiming.retime(robot, paths["case2"], actuators=limits(robot), grid=100)
    fig = ours.figure(dt=1e-2)
    assert len(fig.axes) == 2
    assert len(fig.axes[0].lines) == 3 and len(fig.axes[1].lines) == robot.n_joints + 1


@pytest.mark.parametrize(
    ("change", "field"),
    [
        (
            {
                "reference": SimpleNamespace(
                    t=np.zeros(1), q=np.zeros((1, 7)), qd=np.zeros((1, 7)), qdd=np.zeros((1, 7))
                )
            },
            "reference.t",
        ),
        ({"grid": 1}, "grid"),
        ({"actuators": None}, "actuators"),
        ({"tool_force": float("nan")}, "tool_force"),
        ({"scheme": "midpoint"}, "scheme"),
    ],
)
def test_bad_input_is_refused_naming_the_field(robot, paths, change, field):
    arguments = {"reference": paths["case2"], "actuators": limits(robot), "grid": 50, **change}
    reference = arguments.pop("reference")
    with pytest.raises(InputError, match=rf"^{field}\b") as raised:
        retiming.retime(robot, reference, **arguments)
    assert "\n" not in str(raised.value)


def test_the_retimed_case_1_closed_loop_stays_within_its_actuators_and_on_the_path(robot, paths):
    """The issue's closed loop: case 1 retimed at 800 points under 60 N / 0.05 m/s legs (friction
    held), run by computed force control with the momentum observer and the Kalman estimator (the
    low-force preset's gains and filters), 1 um encoders, a model 10 % heavy, on a plant with those
    actuators: no effort beyond its limit at the true joint velocity (the loop clips at the one it
    sees), and the tip within 0.05 mm of the path (measured 0.025 mm; 0.139 mm on the paper's own
    timing of the path, which starts at speed from rest)."""
    actuators = limits(robot)
    plant = robot.with_parameters(dataclasses.replace(robot.parameters, actuators=actuators))
    reference = vgtarm.retime(plant, paths["case1"], grid=800).reference(1e-3)
    options = vgtarm.PRESETS["low-force"]
    run = vgtarm.simulate(
        plant,
        reference,
        vgtarm.ComputedForceControl.with_gains(options["kp"], options["kv"]),
        observer="momentum",
        observer_gain=options["observer_gain"],
        estimator="kalman",
        estimator_bandwidth_hz=options["estimator_bandwidth_hz"],
        encoder_resolution=1e-6,
        controller_model=plant.parameters.scaled(mass=1.1),
    )
    lower, upper = actuators.bounds(run.qd)
    assert (run.effort >= lower - 1e-9).all() and (run.effort <= upper + 1e-9).all()
    summary = run.summary()
    assert summary["max_tip_error_m"] <= 0.05e-3
    assert summary["actuator_time_at_limit_s"]["v1"] > 0.0  # the timing uses the limits: the loop meets them


@pytest.mark.parametrize(("case", "line"), [("case1", False), ("case2", False), ("case1", True), ("case2", True)])
def test_refinement_keeps_the_resampled_path_within_its_limits_between_grid_points(robot, paths, case, line):
    """On the uniform grid the limits hold at the grid points only: resampled every millisecond, case
    1 exceeds its 60 N by 1.8 N and case 2 by 34 N (where q' vanishes at its corner). Refined, the
    timing is solved under limits MARGIN (0.1 %) tighter and the intervals where the 1 ms resampling
    exceeds an actuator's own bound are halved until none does: then no force, speed or
    acceleration is beyond its limit (force-speed lines too, and with the friction held), and the
    timing is no slower than the uniform grid's by more than the margin's 0.1 % and round-off."""
    actuators = limits(robot, line=line)
    coarse = retiming.retime(robot, paths[case], actuators=actuators, grid=400, refine=0)
    if not line:
        assert retiming.force_excess(robot, coarse.reference(1e-3), actuators).max() > 1.0
    fine = retiming.retime(robot, paths[case], actuators=actuators, grid=400)
    reference = fine.reference(1e-3)
    assert len(fine.s) > 400
    assert retiming.force_excess(robot, reference, actuators).max() <= 1e-12 * 60.0
    assert (np.abs(reference.qd) <= (1 + 1e-12) * actuators.speed).all()
    assert fine.duration <= (1 + 2 * retiming.MARGIN) * coarse.duration


def test_the_retime_command_writes_a_path_that_simulate_and_ik_take(tmp_path, capsys):
    """``vgtarm retime`` on the robot file with actuators: the timing and each joint's use printed,
    and a folder whose path.csv is a tip path vgtarm reads (starting and ending at rest) and whose
    joints.csv holds the retimed joints; a robot without actuators is refused in one line."""
    from vgtarm.app.cli.command import main

    config = Path(__file__).resolve().parents[1] / "examples" / "paper_robot_with_actuators.toml"
    out = tmp_path / "fast"
    assert main(["retime", "--case", "2", "--config", str(config), "--out", str(out), "--grid", "200"]) == 0
    printed = capsys.readouterr().out
    assert "retimed" in printed and "peak force use" in printed
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == [
        "joints.csv",
        "path.csv",
        "phase_plane.png",
    ]
    tip = vgtarm.paths.from_csv(out / "path.csv")
    assert np.linalg.norm(tip.position[0] - vgtarm.paths.case2().position[0]) < 1e-9
    joints = np.loadtxt(out / "joints.csv", delimiter=",", skiprows=1)
    assert joints.shape == (len(tip), 1 + 3 * 7)
    np.testing.assert_array_equal(joints[[0, -1], 8:15], 0.0)  # rest to rest
    assert main(["retime", "--case", "2", "--out", str(tmp_path / "none")]) != 0
    assert "no [actuators] table" in capsys.readouterr().err
    assert not (tmp_path / "none").exists()
    # a tool-axis path (vgtarm ik's flags and refusals): the drill's axis 10 degrees from the vertical
    axis = "0,0.17364817766693,0.98480775301221"
    assert (
        main(["retime", "--case", "1", "--axis", axis, "--config", str(config), "--out", str(out), "--grid", "100"])
        == 0
    )
    assert "retimed" in capsys.readouterr().out
    assert main(["retime", "--case", "1", "--cone", "5", "--config", str(config), "--out", str(tmp_path / "c")]) != 0
    assert "--cone '5': a cone needs its axis" in capsys.readouterr().err
