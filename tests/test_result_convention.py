"""Results say how they ended the same way: ``success``, ``status``, ``message``, ``wall_time_s``;
``check=False`` returns a failed run with its arrays up to the failure instead of raising; a run
becomes a DataFrame and a plot."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.axes import Axes
from matplotlib.figure import Figure

import vgtarm
from vgtarm.control import ComputedForceControl
from vgtarm.simulation import simulate
from vgtarm.simulation.result import MODE_NOT_RUN, SimulationResult

from .test_simulation import smooth_reference

CFC = ComputedForceControl.with_gains(5000.0, 300.0)


def _diverging(robot, *, check):
    """A limp controller that believes the robot weighs nothing: the robot falls out of its limits."""
    weightless = robot.parameters.scaled(mass=1e-3, inertia=1e-3, friction=1e-3)
    limp = ComputedForceControl.with_gains(0.0, 0.0)
    return simulate(robot, smooth_reference(robot, duration=1.0), limp, controller_model=weightless, check=check)


def test_check_false_returns_the_failed_run_that_check_true_raises_with(robot):
    with pytest.raises(vgtarm.SimulationError) as info:
        _diverging(robot, check=True)
    raised = info.value.result
    returned = _diverging(robot, check=False)
    assert not returned.success and returned.status == raised.status != "completed"
    assert returned.message == raised.message and returned.message.startswith("diverged at t = ")
    reached = returned.mode != MODE_NOT_RUN
    assert 0 < reached.sum() < len(returned.t)
    np.testing.assert_array_equal(returned.q[reached], raised.q[reached])  # the same run, bit for bit
    assert np.isnan(returned.q[~reached]).all()
    assert returned.summary()["status"] == returned.status


def test_a_completed_run_says_so(robot):
    run = simulate(robot, smooth_reference(robot, duration=0.1), CFC)
    assert run.success and run.status == "completed" and run.message == "completed"
    assert run.wall_time_s > 0


@pytest.mark.parametrize("check", [1, "yes", None])
def test_check_must_be_a_boolean(robot, check):
    with pytest.raises(vgtarm.InputError, match="check = .*: expected True or False"):
        simulate(robot, smooth_reference(robot, duration=0.01), CFC, check=check)


def test_the_status_survives_save_and_load(robot, tmp_path):
    failed = _diverging(robot, check=False)
    loaded = SimulationResult.load(failed.save(tmp_path / "run"))
    assert (loaded.success, loaded.status, loaded.message) == (False, failed.status, failed.message)


def test_to_dataframe_holds_the_timeseries_columns(robot):
    pandas = pytest.importorskip("pandas")  # the test extra installs it (vgtarm[dataframe])
    run = simulate(robot, smooth_reference(robot, duration=0.1), CFC)
    frame = run.to_dataframe()
    assert isinstance(frame, pandas.DataFrame)
    columns, table = run._table()
    assert list(frame.columns) == columns and len(frame) == len(run.t)
    np.testing.assert_array_equal(frame["t"].to_numpy(), run.t)
    np.testing.assert_array_equal(frame[list(robot.joint_names)].to_numpy(), run.q)
    assert frame["mode"].dtype == np.int8


def test_plot_draws_the_tip_error_into_the_given_axes_or_a_new_one(robot):
    run = simulate(robot, smooth_reference(robot, duration=0.1), CFC)
    ax = Figure().add_subplot()
    assert run.plot(ax) is ax
    np.testing.assert_allclose(ax.lines[0].get_ydata(), run.tip_error * 1e3)
    assert isinstance(run.plot(), Axes)


def test_dt_of_a_one_sample_run_is_the_recorded_period_and_nan_without_it(robot):
    run = simulate(robot, smooth_reference(robot, duration=0.05), CFC)
    one = SimulationResult(
        **{
            **{name: getattr(run, name) for name in SimulationResult.__dataclass_fields__},
            "t": run.t[:1],
            "metadata": {"dt_s": 1e-3},
        }
    )
    assert one.dt == 1e-3
    bare = SimulationResult(**{**{n: getattr(one, n) for n in SimulationResult.__dataclass_fields__}, "metadata": {}})
    assert np.isnan(bare.dt)


def test_ik_results_follow_the_convention(robot):
    path = vgtarm.paths.case1(dt=1e-2, duration=0.5)
    ik = vgtarm.inverse_kinematics(robot, path)
    assert ik.success and ik.status == "completed" and ik.wall_time_s > 0 and ik.message
    point = vgtarm.solve_point(robot, [0.01, 0.0, 0.65])
    assert (point.success, point.status) == (True, "solved") and point.wall_time_s > 0
    assert point.message.startswith("point (0.01, 0, 0.65) m reached")
    far = vgtarm.solve_point(robot, [0.5, 0.0, 0.64])
    assert (far.success, far.status) == (False, "unreachable") and "cannot be reached" in far.message


def test_an_ik_result_becomes_a_dataframe_and_a_plot(robot):
    pytest.importorskip("pandas")
    ik = vgtarm.inverse_kinematics(robot, vgtarm.paths.case1(dt=1e-2, duration=0.5))
    frame = ik.to_dataframe()
    assert list(frame.columns) == list(vgtarm.ik.records.csv_columns(robot.joint_names))
    np.testing.assert_array_equal(frame[list(robot.joint_names)].to_numpy(), ik.q)
    ax = ik.plot()
    assert len(ax.lines) == robot.n_joints
    clearance = np.asarray(ax.lines[0].get_ydata())
    assert ((clearance > 0) & (clearance <= 0.5)).all()  # inside the limits, at most mid-range


def test_records_become_strict_json_alike_for_runs_and_studies():
    """One conversion for summary.json and a study's records: NumPy scalars and arrays become
    numbers and lists, a non-finite number None (strict JSON has no NaN)."""
    import json

    from vgtarm.fileio import json_value

    record = {"a": np.float64("nan"), "b": np.arange(3), "c": (np.int8(2), float("inf")), "d": {"e": np.float32(0.5)}}
    text = json.dumps(json_value(record), allow_nan=False)
    assert json.loads(text) == {"a": None, "b": [0, 1, 2], "c": [2, None], "d": {"e": 0.5}}


# -- inverse kinematics with check=False ---------------------------------------------------------


def _outward(robot, dt=2e-2):
    """From the home tip straight out along x by 0.45 m in 1 s: out of reach about halfway."""
    home = robot.tip_position(robot.parameters.home)
    return vgtarm.paths.waypoints([0.0, 1.0], [home, home + [0.45, 0.0, 0.0]], dt=dt, name="outward")


def _head(path, n):
    """The first ``n`` samples of ``path`` as a path of their own."""
    jerk = None if path.jerk is None else path.jerk[:n]
    return vgtarm.paths.TipPath(
        path.name, path.t[:n], path.position[:n], path.velocity[:n], path.acceleration[:n], jerk
    )


def _assert_rows_are(partial, reference, n):
    """The first ``n`` rows of ``partial`` are ``reference``'s, bit for bit, and the rest are blank."""
    for name in ("q", "qd", "qdd"):
        np.testing.assert_array_equal(getattr(partial, name)[:n], getattr(reference, name), err_msg=name)
        assert np.isnan(getattr(partial, name)[n:]).all(), name
    for name, value in vars(reference.samples).items():
        if isinstance(value, np.ndarray):
            np.testing.assert_array_equal(getattr(partial.samples, name)[:n], value, err_msg=name)
    assert not partial.samples.success[n:].any()
    assert partial.samples.method[n] == "unreachable" and set(partial.samples.method[n + 1 :]) <= {"not solved"}


@pytest.mark.parametrize("rates", ["exact", "finite_difference"])
def test_ik_check_false_returns_the_reachable_prefix_bit_for_bit(robot, rates):
    path = _outward(robot)
    with pytest.raises(vgtarm.UnreachableError) as info:
        robot.inverse_kinematics(path, rates=rates)
    partial = robot.inverse_kinematics(path, rates=rates, check=False)
    assert (partial.success, partial.status, partial.message) == (False, "unreachable", str(info.value))
    n = partial.completed
    assert partial.message.startswith(f"sample {n} at t = ") and 2 <= n < len(path)
    assert len(partial) == len(path) and partial.t is path.t and partial.position is path.position
    prefix = robot.inverse_kinematics(_head(path, n), rates=rates)  # check=True: every sample reached
    assert prefix.success and prefix.completed == n
    _assert_rows_are(partial, prefix, n)
    assert partial.work["n_iterations"] > prefix.work["n_iterations"]  # both solves counted
    assert partial.plot() is not None  # the blank rows leave gaps


def test_ik_check_false_with_the_first_sample_out_of_reach_has_no_rows(robot):
    home = robot.tip_position(robot.parameters.home)
    path = vgtarm.paths.waypoints([0.0, 0.05], [home + [0.5, 0.0, 0.0], home + [0.5, 0.01, 0.0]], dt=1e-2)
    partial = vgtarm.inverse_kinematics(robot, path, check=False)
    assert partial.status == "unreachable" and partial.completed == 0 and partial.message.startswith("sample 0 ")
    assert np.isnan(partial.q).all() and not partial.samples.success.any()
    assert list(partial.samples.method) == ["unreachable"] + ["not solved"] * (len(path) - 1)


def test_ik_check_false_cuts_a_planar_path_at_its_first_point_off_the_plane():
    """Off the plane is found before anything is solved: the farthest point is raised for, the first
    one ends a result; the samples before it are solved alone."""
    from .test_ik_planar import EXAMPLES

    planar = vgtarm.load_robot(EXAMPLES / "planar_module.toml")
    tip = planar.tip_position(planar.parameters.home)
    t = np.linspace(0.0, 0.5, 51)
    zero = np.zeros_like(t)
    position = tip + np.column_stack([np.maximum(t - 0.3, 0.0) * 0.01, 0.02 * t**2, zero])
    velocity = np.column_stack([np.where(t > 0.3, 0.01, 0.0), 0.04 * t, zero])
    acceleration = np.column_stack([zero, np.full_like(t, 0.04), zero])
    path = vgtarm.paths.TipPath("leaving", t, position, velocity, acceleration)
    with pytest.raises(vgtarm.UnreachableError, match=r"^path 'leaving': sample 50 \(t = 0\.5 s\)"):
        planar.inverse_kinematics(path)
    partial = planar.inverse_kinematics(path, check=False)
    assert partial.status == "unreachable" and partial.message.startswith("path 'leaving': sample 31 (t = 0.31 s)")
    assert partial.completed == 31 and partial.task_space == "tip (u2, u3) in its plane"
    _assert_rows_are(partial, planar.inverse_kinematics(_head(path, 31)), 31)


@pytest.mark.parametrize("check", [1, "no", None])
def test_ik_check_must_be_a_boolean(robot, check):
    with pytest.raises(vgtarm.InputError, match="check = .*: expected True or False"):
        robot.inverse_kinematics(vgtarm.paths.case1(dt=1e-2, duration=0.05), check=check)


# -- the robot and the path a result came from ------------------------------------------------------


def test_results_hold_the_robot_and_path_they_came_from_and_pickle_without_the_robot(robot):
    import pickle

    from vgtarm.simulation.reference import JointReference

    path = vgtarm.paths.case1(dt=1e-3, duration=0.1)
    ik = robot.inverse_kinematics(path)
    assert ik.robot is robot and ik.path is path
    assert (ik.robot_name, ik.path_name, ik.robot_fingerprint) == (robot.parameters.name, "case1", robot.fingerprint)
    sent = pickle.loads(pickle.dumps(ik))  # to another process: the names stay, the robot does not
    assert sent.robot is None and sent.robot_name == ik.robot_name and sent.path_name == ik.path_name
    np.testing.assert_array_equal(sent.q, ik.q)
    np.testing.assert_array_equal(sent.path.position, path.position)
    reference = JointReference.of(ik)
    assert (reference.name, reference.robot, reference.robot_fingerprint) == ("case1", ik.robot_name, robot.fingerprint)
    assert JointReference.of(sent).robot == ik.robot_name

    run = simulate(robot, ik, CFC)
    assert run.robot is robot and isinstance(run.reference, JointReference)
    np.testing.assert_array_equal(run.reference.q, run.q_desired)
    moved = pickle.loads(pickle.dumps(run))
    assert moved.robot is None and moved.summary() == run.summary()
    np.testing.assert_array_equal(moved.reference.q, run.reference.q)

    point = vgtarm.solve_point(robot, [0.01, 0.0, 0.65])
    assert point.robot is robot and pickle.loads(pickle.dumps(point)).robot is None


# -- a study's result -------------------------------------------------------------------------------


def _study(failed=False, lost=()):
    from pathlib import Path

    from vgtarm.study.runner import StudyRun

    rows = [
        {"id": f"p{i}", "controller": "cfc", "error": "", "success": True, "message": "completed",
         "max_tip_error_m": 1e-4 * (i + 1)}
        for i in range(4)
    ]  # fmt: skip
    if failed:
        rows[2].update(success=False, error="SimulationError", message="diverged at t = 0.1000 s")
    return StudyRun(rows, 4 + len(lost), 1, 3, int(failed), tuple(lost), 2.5, Path("out"))


def test_a_study_says_how_it_ended():
    done = _study()
    assert (done.success, done.status, done.wall_time_s) == (True, "completed", 2.5)
    assert done.message == "4 runs: 1 already stored, 3 run now, 0 failed, 0 lost"
    failed = _study(failed=True)
    assert (failed.success, failed.status) == (False, "runs_failed")
    assert failed.message.endswith("(first failed: p2: diverged at t = 0.1000 s)")
    lost = _study(lost=("p9",))
    assert (lost.success, lost.status) == (False, "incomplete") and "run the study again" in lost.message


def test_a_study_becomes_a_dataframe_and_a_plot():
    pandas = pytest.importorskip("pandas")
    study = _study(failed=True)
    frame = study.to_dataframe()
    assert isinstance(frame, pandas.DataFrame) and list(frame["id"]) == ["p0", "p1", "p2", "p3"]
    assert list(frame.columns) == list(study.rows[0])
    ax = Figure().add_subplot()
    assert study.plot(ax) is ax
    runs, crosses = ax.lines  # the successful runs, then the failed one
    np.testing.assert_array_equal(runs.get_xdata(), [0, 1, 3])
    np.testing.assert_allclose(runs.get_ydata(), [0.1, 0.2, 0.4])  # mm
    np.testing.assert_array_equal(crosses.get_xdata(), [2])
    with pytest.raises(vgtarm.InputError, match="column = 'error': expected a figure of the study's table"):
        study.plot(column="error")
