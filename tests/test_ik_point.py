"""Inverse kinematics of one tip point: ``vgtarm.ik.solve_point`` and ``vgtarm ik --point`` (issue 27, item 2)."""

from __future__ import annotations

import numpy as np
import pytest

from vgtarm.app.cli.command import main
from vgtarm.errors import InputError
from vgtarm.ik import PointSolution, solve_point
from vgtarm.ik.records import csv_columns

from .conftest import random_configurations


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_forward_kinematics_of_the_answer_hits_the_point(robot, seed):
    q_known = random_configurations(robot, 1, seed=seed, margin=0.03)[0]
    point = robot.tip_position(q_known)  # reachable by construction
    solution = solve_point(robot, point)
    assert isinstance(solution, PointSolution) and solution.success, solution.message
    assert np.abs(robot.tip_position(solution.q) - point).max() <= 1e-9
    assert solution.residual <= 1e-9
    low, high = robot.parameters.lower, robot.parameters.upper
    np.testing.assert_allclose(solution.margins, np.column_stack([solution.q - low, high - solution.q]))
    assert (solution.margins >= 0).all() and np.isnan(solution.orientation_error)


def test_the_point_is_the_joint_limit_optimum_of_a_one_sample_path(robot):
    """The same problem as a path's sample: the eq. 12 optimum, no further from the centre of the
    limits than the configuration the point was made from."""
    q_known = random_configurations(robot, 1, seed=5, margin=0.03)[0]
    solution = solve_point(robot, robot.tip_position(q_known))
    centre = (robot.parameters.lower + robot.parameters.upper) / 2
    weight = 1.0 / (robot.parameters.upper - robot.parameters.lower) ** 2
    assert np.sum(weight * (solution.q - centre) ** 2) <= np.sum(weight * (q_known - centre) ** 2) + 1e-12


def test_a_point_with_an_orientation(robot):
    q_known = random_configurations(robot, 1, seed=3, margin=0.03)[0]
    fk = robot.forward_kinematics(q_known)
    solution = solve_point(robot, fk.tip, rotation=fk.rotation)
    assert solution.success, solution.message
    assert np.abs(robot.tip_position(solution.q) - fk.tip).max() <= 1e-9
    assert solution.orientation_error <= 1e-9


def test_an_unreachable_point_is_a_record_not_an_exception(robot):
    solution = solve_point(robot, [0.5, 0.0, 0.64])
    assert not solution.success
    assert "cannot be reached" in solution.message and "(0.5, 0, 0.64)" in solution.message
    assert solution.residual > 0.1 and solution.q.shape == (robot.n_joints,)
    assert robot.in_joint_range(solution.q)


def test_cli_point_prints_the_configuration_and_margins(capsys, robot):
    point = robot.tip_position(random_configurations(robot, 1, seed=4, margin=0.03)[0])
    text = ",".join(f"{v:.17g}" for v in point)
    assert main(["ik", "--point", text]) == 0
    out = capsys.readouterr().out
    rows = [line.split() for line in out.splitlines() if line.split()[:1] in ([n] for n in robot.joint_names)]
    q = np.array([float(row[1]) for row in rows])
    assert q.shape == (robot.n_joints,)
    assert np.abs(robot.tip_position(q) - point).max() <= 1e-8  # printed with 10 digits
    for word in ("residual", "to min", "to max", "closest", "verified"):
        assert word in out


def test_cli_negative_coordinates_are_values_not_options(capsys):
    assert main(["ik", "--point", "-0.02,0.01,0.64"]) == 0
    assert "verified" in capsys.readouterr().out


def test_a_one_row_path_file_with_dt_is_refused(tmp_path, capsys):
    source = tmp_path / "one.csv"
    source.write_text("t,x,y,z\n0.25,0.01,0,0.65\n")
    assert main(["ik", "--path", str(source), "--dt", "0.01"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--dt '0.01'" in err and "one row" in err


def test_a_one_row_path_file_is_one_point(tmp_path, capsys, robot):
    source, out = tmp_path / "one.csv", tmp_path / "q.csv"
    source.write_text("t,x,y,z\n0.25,0.01,0,0.65\n")
    assert main(["ik", "--path", str(source), "-o", str(out)]) == 0
    lines = out.read_text().splitlines()
    assert lines[0] == ",".join(csv_columns(robot.joint_names)) and len(lines) == 2
    row = np.array(lines[1].split(","), dtype=float)
    assert row[0] == 0.25
    assert np.abs(robot.tip_position(row[4:11]) - [0.01, 0.0, 0.65]).max() <= 1e-9
    assert not row[11:].any()
    assert "one row" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--point", "0.5,0,0.64"], ["cannot be reached", "0.3 m away", "nothing written"]),
        (["--point", "0.5,0"], ["--point", "0.5,0", "3 finite numbers"]),
        (["--point", "0,0,nan"], ["--point", "3 finite numbers"]),
        (["--point", "0,0,0.66", "--case", "1"], ["exactly one of"]),
        (["--point", "0,0,0.66", "--pose", "1,0,0"], ["--pose", "9 finite numbers"]),
        (["--point", "0,0,0.66", "--dt", "0.1"], ["--dt", "no sampling period"]),
    ],
)
def test_bad_or_unreachable_points_give_one_line(tmp_path, capsys, args, words):
    out = tmp_path / "q.csv"
    assert main(["ik", *args, "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("vgtarm: error: ") and err.count("\n") == 1
    for word in words:
        assert word in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("point", "message"),
    [
        ([0.0, 0.0], r"^point\.shape = \(2,\): expected \(3,\)$"),
        ([0.0, np.nan, 0.66], r"^point\[1\] = nan: expected a finite number$"),
        ([True, False, True], r"^point = \[True, False, True\]: expected an array of numbers$"),
        ([0.0, 0.0, 2e3], r"^point = \[0\.0, 0\.0, 2000\.0\]: expected coordinates x, y, z within \+-1000 \(m\)$"),
    ],
)
def test_a_bad_point_is_refused_naming_it(robot, point, message):
    with pytest.raises(InputError, match=message):
        solve_point(robot, point)


def test_cli_point_with_a_rotation(capsys, robot):
    fk = robot.forward_kinematics(random_configurations(robot, 1, seed=6, margin=0.03)[0])
    point = ",".join(f"{v:.17g}" for v in fk.tip)
    rotation = ",".join(f"{v:.17g}" for v in fk.rotation.ravel())
    assert main(["ik", "--point", point, "--pose", rotation]) == 0
    out = capsys.readouterr().out
    assert "orientation of --pose" in out and "orientation error" in out
