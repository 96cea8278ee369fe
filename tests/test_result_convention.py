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
