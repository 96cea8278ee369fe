"""A run saved from Python shows its path's name in a report, not "case 0" (issue 27, item 9)."""

from __future__ import annotations

from vgtarm import paths
from vgtarm.app.reports.html import load_runs, spec_of
from vgtarm.app.reports.runs import table_row
from vgtarm.control import ComputedForceControl
from vgtarm.simulation import SimulationResult, simulate


def test_a_python_run_keeps_its_path_name_in_the_report(robot, tmp_path):
    path = paths.waypoints([0.0, 0.05], [[0.0, 0.0, 0.66], [0.002, 0.0, 0.659]], dt=1e-3, name="my_cut")
    run = simulate(robot, robot.inverse_kinematics(path), ComputedForceControl.with_gains(5000, 300))
    assert run.summary()["reference"] == "my_cut"
    run.save(tmp_path / "saved")
    loaded = SimulationResult.load(tmp_path / "saved")
    spec = spec_of(loaded)
    assert (spec.case, spec.name) == (0, "my_cut")
    assert table_row(spec, loaded.summary(), "saved")[0] == "my_cut"
    (report_run,) = load_runs([tmp_path / "saved"])
    assert report_run.label == "my_cut CFC (saved)" and "case 0" not in report_run.label


def test_a_case_run_still_shows_its_number(robot):
    from vgtarm.experiment.cases import joint_reference, run_case, truncate_reference

    run = run_case(robot, 1, reference=truncate_reference(joint_reference(robot, 1), 0.01))
    spec = spec_of(run)
    assert spec.case == 1 and spec.name == "" and table_row(spec, run.summary())[0] == "1"


def test_the_animation_title_names_the_path_of_a_run_that_is_not_a_case(robot):
    from vgtarm.app.pictures.animation import _title

    path = paths.waypoints([0.0, 0.02], [[0.0, 0.0, 0.66], [0.001, 0.0, 0.66]], dt=1e-3, name="my_cut")
    run = simulate(robot, robot.inverse_kinematics(path), ComputedForceControl.with_gains(5000, 300))
    assert _title(robot, run, 1.0).startswith(f"{robot.parameters.name}: my_cut, CFC")
