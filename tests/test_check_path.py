"""``check_path`` and ``vgtarm check path``: a reference checked against actuator limits.

Checked against independent computations: the efforts of a robot held still at home equal the
gradient of its potential energy (finite differences of ``robot.energy``), the efforts along any
reference equal ``M qdd + C - J_P^T f`` assembled from the mass matrix, the bias forces and the tip
Jacobian, and the violations of case 1 under 60 N / 0.05 m/s legs equal a NumPy recomputation of
the bounds (the force-speed line written out) and of the excesses.
"""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import vgtarm
from vgtarm.errors import InputError
from vgtarm.model.actuators import Actuator, Actuators
from vgtarm.simulation import JointReference
from vgtarm.simulation.limits_check import CUTTING_SPEED, PathCheck, check_path

from .conftest import FD_STEP, assert_close, random_configurations

ROBOT_FILE = Path(vgtarm.__file__).parent / "model" / "data" / "reference_robot.toml"
SAMPLES = 50
DT = 1e-2


def _legs(robot: vgtarm.Robot, force: float, speed: float, line: bool = False) -> Actuators:
    """Every leg the same actuator; the twists none."""
    joints = tuple(None if unit == "rad" else Actuator(force, speed, force_speed=line) for unit in robot.joint_units)
    return Actuators(robot.joint_names, joints)


def _hold_reference(robot: vgtarm.Robot) -> JointReference:
    """The robot still at home for ``SAMPLES`` samples."""
    home = np.asarray(robot.parameters.home, dtype=float)
    q = np.tile(home, (SAMPLES, 1))
    return JointReference(np.arange(SAMPLES) * DT, q, np.zeros_like(q), np.zeros_like(q), name="hold")


def _gravity_hold(robot: vgtarm.Robot) -> np.ndarray:
    """dU/dq at home by central differences of the potential energy: the efforts that hold it still."""
    home = np.asarray(robot.parameters.home, dtype=float)
    steps = np.eye(robot.n_joints) * FD_STEP
    _, up = robot.energy(home + steps, np.zeros_like(steps))
    _, down = robot.energy(home - steps, np.zeros_like(steps))
    return (up - down) / (2 * FD_STEP)


def test_efforts_at_rest_at_home_are_the_gravity_hold(robot: vgtarm.Robot) -> None:
    check = check_path(robot, _hold_reference(robot), actuators=_legs(robot, 1e3, 1.0))
    hold = _gravity_hold(robot)
    assert np.abs(hold).max() > 1.0  # a real load, not zeros
    assert_close(check.efforts, np.tile(hold, (SAMPLES, 1)), rtol=1e-6, atol=1e-6)
    assert check.ok and check.violations() == []
    assert np.all(check.speed_utilisation == 0.0) and np.all(check.acceleration_utilisation == 0.0)
    assert not check.tip_force.any()  # the tool rests: no tool force


def _per_joint(robot: vgtarm.Robot, forces: np.ndarray) -> Actuators:
    return Actuators(robot.joint_names, tuple(Actuator(float(f), 1.0) for f in forces))


def test_hold_passes_above_the_hold_and_fails_just_under_it_on_that_joint(robot: vgtarm.Robot) -> None:
    hold = np.abs(_gravity_hold(robot))
    above = np.maximum(1.01 * hold, 1.0)
    assert check_path(robot, _hold_reference(robot), actuators=_per_joint(robot, above)).ok
    j = int(np.argmax(hold))
    under = above.copy()
    under[j] = hold[j] * (1 - 1e-3)
    check = check_path(robot, _hold_reference(robot), actuators=_per_joint(robot, under))
    assert not check.ok
    (row,) = check.violations()
    assert (row.joint, row.kind, row.unit) == (robot.joint_names[j], "force", "N")
    assert_close(row.excess, hold[j] * 1e-3, rtol=1e-5)
    assert_close(row.excess_percent, 100 * 1e-3 / (1 - 1e-3), rtol=1e-5)
    assert row.limit == pytest.approx(math.copysign(under[j], check.efforts[0, j]))
    assert row.first_time == 0.0 and row.time_beyond == pytest.approx(SAMPLES * DT)
    assert check.force_utilisation[0, j] == pytest.approx(1 / (1 - 1e-3))
    assert "EXCEEDED" in check.table() and robot.joint_names[j] in check.table()


def test_efforts_equal_mass_matrix_bias_and_tool_force(robot: vgtarm.Robot) -> None:
    rng = np.random.default_rng(3)
    q = random_configurations(robot, SAMPLES, seed=3)
    qd = rng.uniform(-0.05, 0.05, q.shape)
    qd[0] = 0.0  # the tool rests: no tool force there
    qdd = rng.uniform(-0.3, 0.3, q.shape)
    reference = JointReference(np.arange(SAMPLES) * DT, q, qd, qdd)
    check = check_path(robot, reference, actuators=_legs(robot, 60.0, 0.05), tool_force=20.0)
    J = robot.tip_jacobian(q)
    V = np.einsum("nij,nj->ni", J, qd)
    speed = np.linalg.norm(V, axis=1)
    f = np.where((speed > CUTTING_SPEED)[:, None], -20.0 * V / np.maximum(speed, 1e-300)[:, None], 0.0)
    expected = np.einsum("nij,nj->ni", robot.mass_matrix(q), qdd) + robot.bias_forces(q, qd)
    expected -= np.einsum("nij,ni->nj", J, f)
    assert_close(check.tip_force, f, rtol=1e-9, atol=1e-12)
    assert_close(check.efforts, expected, rtol=1e-8, atol=1e-9)
    moving = speed > CUTTING_SPEED
    assert moving[1:].all() and not check.tip_force[0].any()
    assert_close(np.linalg.norm(check.tip_force[moving], axis=1), 20.0)


def _bounds(force: float, speed: float, line: bool, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The force bounds at velocities ``v``, written out: a flat band, or the motor's line."""
    if not line:
        return np.full_like(v, -force), np.full_like(v, force)
    upper = np.clip(force * np.minimum(1.0, 1.0 - v / speed), -force, force)
    lower = np.clip(-force * np.minimum(1.0, 1.0 + v / speed), -force, force)
    return lower, upper


@pytest.fixture(scope="module")
def case1(robot: vgtarm.Robot):
    return vgtarm.inverse_kinematics(robot, vgtarm.paths.case1())


@pytest.mark.parametrize("line", [False, True], ids=["flat", "force-speed line"])
def test_case1_under_60_newton_legs_exceeds_where_numpy_says(robot, case1, line: bool) -> None:
    """Case 1 with the paper's 20 N cutting force: which leg exceeds which limit, and by how much."""
    check = check_path(robot, case1, actuators=_legs(robot, 60.0, 0.05, line), tool_force=20.0)
    J = robot.tip_jacobian(case1.q)
    V = np.einsum("nij,nj->ni", J, case1.qd)
    speed = np.linalg.norm(V, axis=1, keepdims=True)
    f = np.where(speed > CUTTING_SPEED, -20.0 * V / speed, 0.0)
    F = np.einsum("nij,nj->ni", robot.mass_matrix(case1.q), case1.qdd) + robot.bias_forces(case1.q, case1.qd)
    F -= np.einsum("nij,ni->nj", J, f)
    expected = {}
    for j, name in enumerate(robot.joint_names):
        if robot.joint_units[j] == "rad":
            continue
        lower, upper = _bounds(60.0, 0.05, line, case1.qd[:, j])
        excess = np.maximum(F[:, j] - upper, lower - F[:, j])
        if (excess > 0).any():
            k = int(np.argmax(excess))
            expected[(name, "force")] = (excess[k], case1.t[k], case1.t[np.argmax(excess > 0)], (excess > 0).sum())
        over = np.abs(case1.qd[:, j]) - 0.05
        if (over > 0).any():
            expected[(name, "speed")] = (
                over.max(),
                case1.t[np.argmax(over)],
                case1.t[np.argmax(over > 0)],
                (over > 0).sum(),
            )
    found = {(v.joint, v.kind): v for v in check.violations()}
    assert set(found) == set(expected)
    if not line:  # the flat band: the two rear-most legs of module 1 (78 N and 84 N peaks)
        assert set(found) == {("s1", "force"), ("v1", "force")}
        assert found["s1", "force"].excess == pytest.approx(18.36, abs=0.01)
        assert found["v1", "force"].excess == pytest.approx(24.26, abs=0.01)
    for key, (excess, worst, first, count) in expected.items():
        row = found[key]
        assert row.excess == pytest.approx(excess, rel=1e-6)
        assert (row.worst_time, row.first_time) == (pytest.approx(worst), pytest.approx(first))
        assert row.time_beyond == pytest.approx(count * check.dt)
    assert not check.ok
    for name in {joint for joint, _ in expected}:
        assert any(line.startswith(name) and "EXCEEDED" in line for line in check.table().splitlines())


def test_a_desired_path_is_solved_first(robot: vgtarm.Robot) -> None:
    path = vgtarm.paths.case2(DT)
    actuators = _legs(robot, 60.0, 0.05)
    direct = check_path(robot, path, actuators=actuators, tool_force=20.0)
    solved = check_path(robot, robot.inverse_kinematics(path), actuators=actuators, tool_force=20.0)
    assert_close(direct.efforts, solved.efforts, rtol=1e-12, atol=1e-12)
    home = robot.tip_position(np.asarray(robot.parameters.home, dtype=float))
    cycle = vgtarm.toolpaths.drilling(
        [0.0, 0.02, 0.67], [0.0, 0.28, 0.96], 0.01, start=home, start_axis=[0, 0, 1], dt=DT
    )
    direct = check_path(robot, cycle, actuators=actuators)
    solved = check_path(robot, robot.inverse_kinematics(cycle.tip, **cycle.task(robot)), actuators=actuators)
    assert direct.reference == "drilling"
    assert_close(direct.efforts, solved.efforts, rtol=1e-12, atol=1e-12)


def test_csv_figure_and_names_that_would_break_columns(robot, tmp_path: Path) -> None:
    check = check_path(robot, _hold_reference(robot), actuators=_legs(robot, 40.0, 0.05))
    written = check.to_csv(tmp_path / "check.csv")
    table = np.loadtxt(written, delimiter=",", skiprows=1)
    header = written.read_text().splitlines()[0].split(",")
    assert_close(table[:, header.index("F_s1")], check.efforts[:, 0], rtol=1e-9)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["check.csv"]  # nothing partial left beside it
    (tmp_path / "folder.csv").mkdir()
    with pytest.raises(InputError, match="folder.csv"):
        check.to_csv(tmp_path / "folder.csv")
    figure = check.figure()
    assert len(figure.axes) == 2 * robot.n_joints
    figure.savefig(tmp_path / "check.png")
    evil = dataclasses.replace(
        check, joint_names=("s\x1b[31m1\nX" + "y" * 40, *check.joint_names[1:]), robot="r\nobot", reference="a\rb"
    )
    text = evil.table()
    assert "\x1b" not in text and "\r" not in text
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("joint"))
    rows = lines[start : start + 1 + robot.n_joints]
    assert rows[1].startswith("s\\x1b[31m1\\~")  # escaped, cut to its column
    limited = [row for row, unit in zip(rows[1:], robot.joint_units, strict=True) if unit != "rad"]
    assert len({row.index(" %") for row in limited}) == 1  # every cell after the name in its column


def test_bad_arguments_are_refused_in_one_line(robot: vgtarm.Robot) -> None:
    reference = _hold_reference(robot)
    with pytest.raises(InputError, match="actuators") as caught:
        check_path(robot, reference)  # the reference robot has no [actuators] table
    assert "\n" not in str(caught.value)
    with pytest.raises(InputError, match="tool_force"):
        check_path(robot, reference, actuators=_legs(robot, 60.0, 0.05), tool_force=-1.0)
    with pytest.raises(InputError, match="actuators.names"):
        check_path(robot, reference, actuators=Actuators(("a",), (None,)))
    short = JointReference(reference.t, reference.q[:, :3], reference.qd[:, :3], reference.qdd[:, :3])
    with pytest.raises(InputError, match="reference.q.shape"):
        check_path(robot, short, actuators=_legs(robot, 60.0, 0.05))
    assert isinstance(check_path(robot, reference, actuators=_legs(robot, 60.0, 0.05)), PathCheck)


# -- the command line ------------------------------------------------------------------------------


def _robot_file(folder: Path, actuators: str | None) -> Path:
    text = ROBOT_FILE.read_text()
    if actuators is not None:
        text += f"\n[actuators]\n{actuators}\n"
    path = folder / "robot.toml"
    path.write_text(text)
    return path


def _vgtarm(folder: Path, *argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "vgtarm", *argv], capture_output=True, text=True, cwd=folder, timeout=300
    )


def test_cli_exceeded_gives_1_with_the_table_and_writes_the_figure(tmp_path: Path) -> None:
    _robot_file(tmp_path, "legs = { force = 60.0, speed = 0.05 }")
    done = _vgtarm(
        tmp_path, "check", "path", "--case", "case1", "--config", "robot.toml", "--tool-force", "20",
        "--figure", "check.png", "--csv", "check.csv", "-q",
    )  # fmt: skip
    assert done.returncode == 1, done.stderr
    assert "2 limits exceeded: s1 force, v1 force" in done.stdout
    assert (tmp_path / "check.png").stat().st_size > 0 and (tmp_path / "check.csv").stat().st_size > 0


def test_cli_within_generous_limits_gives_0_and_writes_its_folder(tmp_path: Path) -> None:
    _robot_file(tmp_path, "legs = { force = 500.0, speed = 1.0 }\ntwists = { force = 1.0, speed = 10.0 }")
    done = _vgtarm(tmp_path, "check", "path", "--case", "case1", "--config", "robot.toml", "--out", "out", "-q")
    assert done.returncode == 0, done.stderr
    assert "within every limit" in done.stdout
    assert {"path_check.txt", "path_check.csv", "path_check.png"} <= {p.name for p in (tmp_path / "out").iterdir()}


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--case", "case1"], "has no [actuators] table"),
        (["--case", "case1", "--config", "robot.toml", "--tool-force", "abc"], "--tool-force"),
        (["--case", "case1", "--config", "robot.toml", "--tool-force", "-5"], "--tool-force"),
        (["--case", "case3", "--config", "robot.toml"], "--case"),
        (["--config", "robot.toml"], "give exactly one"),
        (["--case", "case1", "--config", "robot.toml", "--cone", "5"], "--cone '5': a cone needs its axis"),
        (["--case", "case1", "--config", "robot.toml", "--axis", "0,0,2"], "--axis"),
    ],
    ids=["no actuators", "tool force not a number", "negative tool force", "unknown case", "no path", "cone", "axis"],
)
def test_cli_bad_input_gives_2_in_one_line(tmp_path: Path, argv: list[str], message: str) -> None:
    _robot_file(tmp_path, "legs = { force = 60.0, speed = 0.05 }")
    done = _vgtarm(tmp_path, "check", "path", *argv, "-q")
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and message in done.stderr, done.stderr
    assert done.stdout == "" and "Traceback" not in done.stderr


def test_cli_checks_the_joints_of_a_tool_axis_task(robot: vgtarm.Robot, tmp_path: Path) -> None:
    """``--axis`` (vgtarm ik's flag): the joint path of the drill's axis held along case 1, whose
    efforts are those of that IK result (not the tip-only reference's)."""
    _robot_file(tmp_path, "legs = { force = 500.0, speed = 1.0 }")
    axis = "0,0.17364817766693,0.98480775301221"
    done = _vgtarm(tmp_path, "check", "path", "--case", "1", "--axis", axis, "--config", "robot.toml", "--csv", "a.csv")
    assert done.returncode == 0, done.stderr
    ik = vgtarm.inverse_kinematics(robot, vgtarm.paths.case1(), axis=[0.0, 0.17364817766693, 0.98480775301221])
    F = robot.inverse_dynamics(ik.q, ik.qd, ik.qdd)
    peak = f"{np.abs(F[:, 1]).max():.4g} N"
    assert peak in done.stdout, (peak, done.stdout)


def test_cli_no_actuators_in_a_file_names_the_file_and_the_docs(tmp_path: Path) -> None:
    _robot_file(tmp_path, None)
    done = _vgtarm(tmp_path, "check", "path", "--case", "1", "--config", "robot.toml", "-q")
    assert done.returncode == 2
    assert "robot.toml" in done.stderr and "docs/actuators.md" in done.stderr


def test_check_mujoco_still_has_its_options(tmp_path: Path) -> None:
    done = _vgtarm(tmp_path, "check", "mujoco", "--help")
    assert done.returncode == 0
    assert all(flag in done.stdout for flag in ("--states", "--seed", "--digits", "--config"))
