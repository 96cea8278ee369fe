"""A tool-axis task in a run: ``vgtarm simulate --axis / --cone / --entry-point``, ``vgtarm.Experiment(axis=...)``
and a study's ``axis`` parameter (issue 36, item 4: the closed loop on the tool tasks, as a user sets it up).

The reference's joints are checked against the physics of the task (the tool's axis from the forward
kinematics of the desired joints lies along the axis asked for, or through the entry point), and a run's
summary gives the axis error; a run without a tool task is the run it was.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

import vgtarm
from vgtarm.app.cli import main
from vgtarm.errors import InputError

#: A drill tilted 15 degrees from the vertical about the base x axis, written as a user types it.
TILTED = (0.0, math.sin(math.radians(15.0)), math.cos(math.radians(15.0)))
TILTED_TEXT = ",".join(repr(v) for v in TILTED)
#: A point 0.16 m below case 1's circle (whose centre is at z = 0.66 m): the keyhole.
BELOW = (0.0, 0.0, 0.5)


@pytest.fixture(scope="module")
def robot() -> vgtarm.Robot:
    return vgtarm.load_robot()


def test_an_experiment_holds_the_tool_axis_along_the_axis_asked_for(robot):
    experiment = vgtarm.Experiment(case=1, robot=robot, axis=TILTED, duration=0.3)  # past the 0.2 s transient
    assert experiment.axis == TILTED_TEXT  # three numbers written back exactly (repr)
    reference = experiment.reference()
    assert reference.task == "axis"
    axes = robot.tool_axis(reference.q)  # the forward kinematics of the desired joints
    assert np.abs(axes - np.array(TILTED)).max() < 1e-9
    np.testing.assert_allclose(
        robot.tip_position(reference.q), experiment.desired(robot).position[: len(reference.q)], atol=1e-9
    )
    summary = experiment.run().summary()
    assert summary["success"] and 0.0 < summary["max_axis_error_rad"] < 2e-3
    assert summary["max_axis_error_after_transient_rad"] <= summary["max_axis_error_rad"]


def test_an_experiment_through_an_entry_point_keeps_the_axis_on_it(robot):
    experiment = vgtarm.Experiment(case=1, robot=robot, entry_point=BELOW, duration=0.1)
    reference = experiment.reference()
    tip, rotation = robot.tool_frame(reference.q)
    offset = tip - np.array(BELOW)
    distance = np.linalg.norm(np.cross(offset, rotation[:, :, 2]), axis=1)  # of the point from the axis line
    assert distance.max() < 1e-9
    assert (np.einsum("ij,ij->i", offset, rotation[:, :, 2]) > 0).all()  # the tool advances away from it
    summary = experiment.run().summary()
    assert summary["success"] and 0.0 < summary["max_entry_distance_m"] < 5e-5


def test_without_a_tool_task_the_inverse_kinematics_is_the_tip_alone(robot):
    experiment = vgtarm.Experiment(case=1, robot=robot)
    assert experiment.ik_options() == {} and experiment.tool_task() == {}
    assert "max_axis_error_rad" not in experiment.replace(duration=0.02).run().summary()


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (
            {"axis": "0,0,2"},
            "axis = [0.0, 0.0, 2.0]: expected a unit vector (length 1 within 1e-09), its length is 2; normalised: "
            "[0, 0, 1]",
        ),
        ({"axis": "0,0"}, "axis '0,0': expected 3 finite numbers separated by commas"),
        ({"axis": (0.0, float("nan"), 1.0)}, "axis"),
        ({"cone_degrees": 5.0}, "cone_degrees 5.0: a cone needs its axis"),
        ({"axis": "0,0,1", "cone_degrees": 90.0}, "cone_degrees 90.0: expected a half-angle in (0, 90) degrees"),
        ({"axis": "0,0,1", "entry_point": "0,0,0.5"}, "axis and entry_point: expected one of them"),
        ({"entry_point": "0,0.5"}, "entry_point '0,0.5': expected 3 finite numbers"),
    ],
)
def test_a_tool_task_that_is_not_one_is_refused_in_one_line_naming_the_field(options, message):
    with pytest.raises(InputError) as caught:
        vgtarm.Experiment(case=1, **options)
    text = str(caught.value)
    assert message in text and "\n" not in text, text


def test_the_command_runs_a_tool_axis_task_and_prints_and_writes_its_axis_error(tmp_path, capsys):
    out = tmp_path / "drill"
    status = main(
        ["simulate", "--case", "1", "--axis", TILTED_TEXT, "--cone", "5", "--duration", "0.05", "--out", str(out), "-q"]
    )
    printed = capsys.readouterr().out
    assert status == 0
    assert "max_axis_error_rad" in printed
    summary = json.loads((out / "summary.json").read_text())
    assert summary["max_axis_error_rad"] < 2e-3 and summary["success"]


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--axis", "0,0,2"], "--axis = [0.0, 0.0, 2.0]: expected a unit vector"),
        (["--cone", "5"], "--cone 5.0: a cone needs its axis, --axis X,Y,Z"),
        (["--axis", "0,0,1", "--entry-point", "0,0,0.5"], "--axis and --entry-point: expected one of them"),
        (["--entry-point", "0,0.06,0.66"], "--entry-point = [0.0, 0.06, 0.66]: the tip's path passes 0 m from it"),
    ],
)
def test_the_command_refuses_a_tool_task_in_one_line_naming_the_flag(flags, message, tmp_path, capsys):
    out = tmp_path / "run"
    status = main(["simulate", "--case", "1", *flags, "--duration", "0.05", "--out", str(out), "-q"])
    err = capsys.readouterr().err.strip().splitlines()
    assert status != 0 and len(err) == 1 and message in err[0], err
    assert not out.exists()


def test_a_study_varies_the_tool_axis_and_records_its_error(tmp_path: Path, capsys):
    study = tmp_path / "axis.toml"
    study.write_text(
        '[study]\nname = "drill tilt"\ncase = 1\ndt = 0.001\nduration = 0.05\nseeds = [0]\n\n'
        f'[grid]\ncontroller = "cfc"\naxis = ["0,0,1", "{TILTED_TEXT}"]\n'
    )
    out = tmp_path / "runs"
    assert main(["study", "run", str(study), "--out", str(out), "-q"]) == 0
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert sorted(row["axis"] for row in rows) == sorted(["0,0,1", TILTED_TEXT])
    assert all(row["success"] == "True" and float(row["max_axis_error_rad"]) < 2e-3 for row in rows)
    assert len({row["id"] for row in rows}) == 2
