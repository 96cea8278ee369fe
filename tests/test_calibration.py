"""Kinematic calibration (vgtarm.calibration.kinematic): the AD identification Jacobian against
central differences of the compiled robot, the identifiability analysis against an analytic null
direction, the fit on synthetic data against the issue's targets and scipy's least_squares, the
corrected robot file, the measurement file's refusals and the command line."""

from __future__ import annotations

import argparse
import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest
import scipy.optimize

import vgtarm
from vgtarm.app.cli.calibrate import CALIBRATE_FILES, add_parser
from vgtarm.calibration import kinematic as K
from vgtarm.errors import InputError
from vgtarm.fileio import OutputPathError

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
NOISE = 0.05e-3
#: The two formats: the paper robot's fixed model and the same robot as a stack (which has a tool
#: point, so one undetermined direction: the twist height against the tool's z).
ROBOTS = (None, str(EXAMPLES / "paper_robot.toml"))


@pytest.fixture(scope="module", params=ROBOTS, ids=("paper", "stack"))
def case(request):
    """A robot, its planned poses, a built robot's parameters and the fit of its synthetic data."""
    robot = vgtarm.load_robot(request.param)
    plan = K.plan_poses(robot, 50, seed=0)
    truth = K.perturbed_values(robot, seed=1, lengths=2e-3, offsets=2e-3)
    measured = K.synthetic_measurements(robot, plan.q, truth, noise=NOISE, seed=2)
    return robot, plan, truth, measured, K.calibrate(robot, measured)


def _tool(robot, x, q):
    """The tool point of readings ``q`` for parameters ``x``, through the compiled robot."""
    spec = K.calibration_parameters(robot)
    true_q = q.copy()
    true_q[:, list(spec.offset_joint)] -= x[spec.n_lengths :]
    return robot.with_parameters(K.corrected_parameters(robot, x)).tool_frame(true_q)


@pytest.mark.parametrize("config", ROBOTS, ids=("paper", "stack"))
def test_lengths_are_the_robot_files_fields_in_the_parameter_vector(config):
    robot = vgtarm.load_robot(config)
    spec = K.calibration_parameters(robot)
    for k in range(spec.n_lengths):
        x = spec.nominal.copy()
        x[k] += 1e-3
        moved = K.corrected_parameters(robot, x).vector() - robot.parameter_vector
        expected = np.zeros_like(moved)
        expected[spec.vector_index[k]] = 1e-3
        np.testing.assert_allclose(moved, expected, atol=1e-15, err_msg=spec.names[k])


@pytest.mark.parametrize("config", ROBOTS, ids=("paper", "stack"))
def test_the_ad_jacobian_matches_central_differences_of_the_compiled_robot(config):
    robot = vgtarm.load_robot(config)
    spec = K.calibration_parameters(robot)
    q = K.candidate_poses(robot, 40, seed=3)[:6]
    x = K.perturbed_values(robot, seed=4)
    rotation = _tool(robot, x, q)[1] @ np.array([K._exp(w) for w in 0.01 * np.ones((len(q), 3))])
    model = K.ToolModel(robot, orientation=True)
    values, J = model.evaluate(q, x, rotation)

    def rows(xk):  # the model's rows from the compiled robot, the orientation residual in NumPy
        tip, R = _tool(robot, xk, q)
        skew = np.swapaxes(rotation, 1, 2) @ R - np.swapaxes(R, 1, 2) @ rotation
        return np.column_stack([tip, 0.5 * np.stack([skew[:, 2, 1], skew[:, 0, 2], skew[:, 1, 0]], axis=1)])

    np.testing.assert_allclose(values, rows(x), atol=1e-14)
    h = 6e-6  # about eps**(1/3) times the lengths' size
    for k in range(spec.size):
        step = np.zeros(spec.size)
        step[k] = h
        fd = (rows(x + step) - rows(x - step)) / (2 * h)
        np.testing.assert_allclose(J[:, :, k], fd, atol=2e-8, err_msg=spec.names[k])


def test_the_paper_robots_lengths_and_offsets_are_all_determined(case):
    robot, plan, *_ = case
    analysis = plan.identifiability
    if robot.is_stack:
        # tip = O2 + height u3 + C03 tool, C03 u3 = u3: height and tool z move the tip alike
        spec = K.calibration_parameters(robot)
        height, tool_z = spec.names.index("module2.twist.height"), spec.names.index("end_effector.tool[2]")
        direction = np.zeros(spec.size)
        direction[[height, tool_z]] = [1 / math.sqrt(2), -1 / math.sqrt(2)]
        assert analysis.null_space.shape[1] == 1
        assert abs(abs(float(analysis.null_space[:, 0] @ direction)) - 1) < 1e-9
        assert analysis.combinations == ("0.707 module2.twist.height - 0.707 end_effector.tool[2]",)
        assert analysis.status[tool_z] == "held" and analysis.status[height] == "given held"
        assert {s for i, s in enumerate(analysis.status) if i not in (height, tool_z)} == {"determined"}
    else:
        assert analysis.rank == len(analysis.names) and set(analysis.status) == {"determined"}
    assert analysis.singular_values[-1 - analysis.null_space.shape[1]] > 1e3 * analysis.tolerance


def test_planned_poses_are_better_conditioned_than_random_ones(case):
    robot, plan, *_ = case
    assert plan.condition_number < 0.6 * np.median(plan.random_condition_numbers)
    assert robot.is_assemblable(plan.q, K.DEFAULT_MARGIN).all()
    lower, upper = robot.joint_limits()
    assert ((plan.q >= lower) & (plan.q <= upper)).all()


def test_the_fit_meets_the_targets_on_synthetic_data(case):
    robot, plan, truth, measured, fit = case
    assert fit.success, fit.message
    assert fit.rms_residual <= 1.1 * NOISE
    status = np.array(fit.status)
    held = status == "held"
    # the truth moved along the undetermined directions until the held parameters are nominal: the
    # same tool positions, so the point the fit can find
    null = fit.identifiability.null_space
    shift = np.linalg.solve(null[held], fit.nominal[held] - truth[held]) if held.any() else np.zeros(0)
    reachable = truth + null @ shift
    z = (fit.values - reachable) / fit.standard_errors
    assert np.all(np.abs(z[~held]) < 3), dict(zip(fit.names, np.round(z, 2), strict=True))
    np.testing.assert_array_equal(fit.values[held], fit.nominal[held])
    assert np.isnan(fit.standard_errors[held]).all()


def test_scipy_least_squares_finds_the_same_optimum(case):
    robot, _, _, measured, fit = case
    problem = K.least_squares_problem(robot, measured)
    found = scipy.optimize.least_squares(
        problem.residuals, problem.z0, jac=problem.jacobian, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15
    )
    free = fit.identifiability.free
    # both stop within 1e-10 m of the optimum: far below its standard errors (5 um and up)
    assert np.abs(problem.full(found.x) - fit.values)[free].max() <= 1e-4 * fit.standard_errors[free].min()
    ours = problem.residuals(fit.values[free])
    assert abs(ours @ ours - found.fun @ found.fun) <= 1e-9 * (ours @ ours)


def test_the_corrected_robot_file_loads_back_with_the_fitted_tool_positions(case, tmp_path):
    robot, _, _, measured, fit = case
    path = K.write_robot_file(tmp_path / "built.toml", fit.robot_toml())
    loaded = vgtarm.load_robot(path)
    assert loaded.parameters == fit.parameters  # every field read back as written, bit for bit
    q = measured.q.copy()
    spec = K.calibration_parameters(robot)
    q[:, list(spec.offset_joint)] -= fit.values[spec.n_lengths :]
    np.testing.assert_allclose(loaded.tip_position(q), measured.tip - fit.residuals[:, :3], atol=1e-12)
    K.write_robot_file(path, fit.robot_toml())  # its own file: replaced
    foreign = tmp_path / "mine.toml"
    foreign.write_text("# my robot\n")
    with pytest.raises(OutputPathError, match="not written by vgtarm calibrate"):
        K.write_robot_file(foreign, fit.robot_toml())
    assert foreign.read_text() == "# my robot\n"


def test_orientation_measurements_are_fitted_too():
    robot = vgtarm.load_robot(str(EXAMPLES / "paper_robot.toml"))
    q = K.plan_poses(robot, 20, seed=5, passes=0).q
    truth = K.perturbed_values(robot, seed=6)
    measured = K.synthetic_measurements(robot, q, truth, orientation=True, orientation_noise=1e-4, seed=7)
    fit = K.calibrate(robot, measured, orientation_noise=1e-4)
    assert fit.success and fit.residuals.shape == (20, 6)
    assert 0.7 < fit.sigma < 1.3  # the weighted residuals have the noise assumed on both kinds
    determined = np.array(fit.status) == "determined"
    assert np.all(np.abs(fit.values - truth)[determined] < 3 * fit.standard_errors[determined])


def _write(path: Path, robot, q, tip) -> Path:
    path.write_text(K.Measurements(np.atleast_2d(q), np.atleast_2d(tip)).to_csv(robot.joint_names))
    return path


def test_a_measurement_file_round_trips(tmp_path, robot):
    q = K.candidate_poses(robot, 20, seed=8)[:6]
    measured = K.synthetic_measurements(robot, q, K.calibration_parameters(robot).nominal, orientation=True)
    path = tmp_path / "m.csv"
    path.write_text(measured.to_csv(robot.joint_names))
    back = K.read_measurements(path, robot)
    np.testing.assert_array_equal(back.q, measured.q)
    np.testing.assert_array_equal(back.tip, measured.tip)
    assert back.rotation is not None
    np.testing.assert_allclose(back.rotation, measured.rotation, atol=1e-15)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda q, tip: (q, np.where(np.arange(18).reshape(6, 3) == 8, np.nan, tip)), r"row 3 \(line 4\): z = nan"),
        (lambda q, tip: (q + np.eye(1, q.shape[1], 0)[0] * (0.5 - q[0, 0]), tip), r"row \d+: s1 = 0\.5 m: expected"),
        (lambda q, tip: (q[:3], tip[:3]), r"3 poses give 9 residuals for 11 parameters: expected at least 4 poses"),
    ],
    ids=("nan", "outside-limits", "too-few"),
)
def test_a_bad_measurement_file_is_refused_naming_the_row(tmp_path, robot, edit, message):
    q = K.candidate_poses(robot, 20, seed=9)[:6]
    tip = robot.tip_position(q)
    q, tip = edit(q, tip)
    with pytest.raises(InputError, match=message):
        K.read_measurements(_write(tmp_path / "m.csv", robot, q, tip), robot)


def test_a_pose_that_cannot_be_assembled_is_refused_naming_the_row(tmp_path, robot):
    lower, upper = robot.joint_limits()
    rng = np.random.default_rng(10)
    inside = lower + (upper - lower) * rng.random((500, robot.n_joints))
    broken = inside[~robot.is_assemblable(inside)][0]
    q = K.candidate_poses(robot, 20, seed=9)[:6]
    q[4] = broken
    tip = np.zeros((6, 3))
    with pytest.raises(InputError, match=r"row 5: the legs .* cannot be assembled"):
        K.read_measurements(_write(tmp_path / "m.csv", robot, q, tip), robot)


def test_a_header_without_a_joint_is_refused(tmp_path, robot):
    path = tmp_path / "m.csv"
    path.write_text("s1,v1,x,y,z\n0.3,0.3,0,0,0\n")
    with pytest.raises(InputError, match=r"line 1: header .* expected the columns s1,v1,p1"):
        K.read_measurements(path, robot)


def _run(*argv: str) -> int:
    parser = argparse.ArgumentParser()
    add_parser(parser.add_subparsers())
    args = parser.parse_args(["calibrate", *argv])
    return args.run(args)


def test_the_command_plans_poses_then_calibrates_from_their_measurements(tmp_path, robot, capsys):
    assert _run("--plan-poses", "30", "--out", str(tmp_path / "plan")) == 0
    plan = K.read_measurements(tmp_path / "plan" / "poses.csv", robot)  # the nominal x, y, z
    truth = K.perturbed_values(robot, seed=11)
    measured = K.synthetic_measurements(robot, plan.q, truth, seed=12)
    path = tmp_path / "measured.csv"
    path.write_text(measured.to_csv(robot.joint_names))
    assert _run("--measurements", str(path), "--out", str(tmp_path / "fit")) == 0
    folder = tmp_path / "fit"
    assert {p.name for p in folder.iterdir()} >= set(CALIBRATE_FILES)
    loaded = vgtarm.load_robot(folder / "robot.toml")
    report = (folder / "report.md").read_text()
    assert "geometry.module1.b" in report and "rank 11 of 11" in report
    table = np.genfromtxt(folder / "parameters.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    np.testing.assert_allclose(loaded.parameter_vector[:5], table["fitted"][:5].astype(float), rtol=0, atol=1e-15)
    assert "condition number" in (tmp_path / "plan" / "plan.md").read_text()


def test_the_calibrated_model_brings_the_closed_loop_near_the_exact_models():
    """examples/calibration/closed_loop.py, case 2 with the tool force and the observer on a built
    robot (lengths +-2 mm): the calibrated controller model within 10 um of the exact one's tip
    error (measured 3.6 um on this seed), the nominal model over 20 times worse (measured 1.72 mm)."""
    spec = importlib.util.spec_from_file_location("closed_loop", EXAMPLES / "calibration" / "closed_loop.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    found = {name: figures["max_m"] for name, figures in module.run_settings("observer, ideal sensing", 1).items()}
    assert found["calibrated"] <= found["exact"] + 10e-6, found
    assert found["nominal"] >= 20 * found["calibrated"], found


def test_the_reports_escape_the_robots_name_as_markdown():
    """A robot named with Markdown and HTML in it: the report shows the name as written, no markup."""
    import dataclasses

    from vgtarm.app.cli.calibrate import _plan_report
    from vgtarm.markup import md_text

    robot = vgtarm.load_robot()
    odd = "*bold* [link](http://x) <b>tag</b> `code`"
    named = robot.with_parameters(dataclasses.replace(robot.parameters, name=odd))
    plan = K.plan_poses(named, 12, seed=0, candidates=300)
    text = _plan_report(named, plan, 0.05e-3)
    assert f"# Measurement poses for {md_text(odd)}" in text.splitlines()[0]
    assert odd not in text
