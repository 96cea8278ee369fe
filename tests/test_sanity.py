"""Physical sanity and one-line errors at the public boundary (issue 14, items 6 and 7).

Joint values far outside the limits, sample spacings that turn rounding into huge rates, a
reference solved for another robot, a bad initial state, and wrong types or values given to the
API: each ends in one line of the project's hierarchy, never in silent garbage or a built-in
exception.
"""

from __future__ import annotations

import dataclasses
import math
import pathlib

import numpy as np
import pytest

import vgtarm
from vgtarm import ga, paths
from vgtarm.app.cli.command import build_parser, main
from vgtarm.control import ComputedForceControl, Gains, SwitchingControl
from vgtarm.errors import AssemblyError, InputError, PathError, SimulationError, VgtarmError
from vgtarm.ik import rates as rate_modes
from vgtarm.model.parameters import JOINT_UNITS
from vgtarm.model.sanity import SANE_TURNS, SANE_WIDENING
from vgtarm.simulation import JointReference, SimulationResult, simulate
from vgtarm.simulation.checks import REFERENCE_TIP_TOLERANCE
from vgtarm.simulation.result import MODE_NOT_RUN

HOME_LEGS = ["0.2844292531", "0.2844292531", "0.3753664876"] * 2


def one_line(error: BaseException) -> str:
    text = str(error)
    assert "\n" not in text, text
    return text


def run(capsys, *argv):
    status = main(list(argv))
    out, err = capsys.readouterr()
    return status, out, err


@pytest.fixture(scope="module")
def short_ik(robot):
    """The inverse kinematics of the first 20 ms of case 1 on the reference robot."""
    return robot.inverse_kinematics(paths.case1(duration=0.02))


@pytest.fixture(scope="module")
def cfc():
    return ComputedForceControl.with_gains(5000.0, 300.0)


# -- joint values far outside the limits ---------------------------------------------------------


def test_joint_range_is_the_limits_widened(robot):
    """Lengths: ten spans on each side and not below 0; angles: a thousand turns on each side."""
    p = robot.parameters
    low, high = robot.joint_range()
    span = p.upper - p.lower
    for i, unit in enumerate(JOINT_UNITS):
        if unit == "m":
            assert low[i] == pytest.approx(max(p.lower[i] - SANE_WIDENING * span[i], 0.0))
            assert high[i] == pytest.approx(p.upper[i] + SANE_WIDENING * span[i])
        else:
            assert low[i] == pytest.approx(p.lower[i] - SANE_TURNS * 2 * math.pi)
            assert high[i] == pytest.approx(p.upper[i] + SANE_TURNS * 2 * math.pi)
    assert low[0] == 0.0 and high[0] == pytest.approx(1.76)  # legs 0.22..0.36 m
    assert high[6] == pytest.approx(math.pi + 2000 * math.pi)


def test_twist_values_inside_the_range_are_evaluated_correctly(robot):
    """A twist of several turns is accepted and gives the kinematics of its angle modulo 2 pi."""
    q = robot.parameters.home.copy()
    q[6] = 0.3
    far = q.copy()
    far[6] = 0.3 + 8 * 2 * math.pi  # eight turns on, inside the accepted +-66 rad
    assert robot.in_joint_range(far)
    np.testing.assert_allclose(robot.forward_kinematics(far).rotation, robot.forward_kinematics(q).rotation, atol=1e-12)


@pytest.mark.parametrize(
    ("joint", "value", "shown"),
    [
        (0, 1e300, "s1 = 1e+300 m"),
        (0, 1e20, "s1 = 1e+20 m"),
        (4, 2.0, "v2 = 2.0 m"),
        (6, 1e20, "psi3 = 1e+20 rad"),
        (6, -1e4, "psi3 = -10000.0 rad"),
    ],
)
def test_joint_values_far_outside_the_limits_are_refused(robot, joint, value, shown):
    q = robot.parameters.home.copy()
    q[joint] = value
    if joint < 3:  # a module whose three legs grow together stays assemblable: only the range stops it
        q[:3] = value
    for method in (robot.forward_kinematics, robot.tip_position, robot.mass_matrix, robot.tip_jacobian):
        with pytest.raises(InputError, match="outside the accepted range") as info:
            method(q)
        assert shown in one_line(info.value)
    with pytest.raises(InputError, match="outside the accepted range"):
        robot.forward_dynamics(q, np.zeros(7), np.zeros(7))
    assert not robot.in_joint_range(q)


def test_a_batch_names_the_configuration(robot):
    q = np.tile(robot.parameters.home, (3, 1))
    q[2, 6] = 1e9
    with pytest.raises(InputError, match=r"psi3 = 1000000000.0 rad \(configuration \(2,\)\)"):
        robot.tip_position(q)


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_non_finite_joint_values_name_the_joint(robot, value):
    q = robot.parameters.home.copy()
    q[6] = value
    with pytest.raises(InputError, match=r"q\[6\] \(psi3\)"):
        robot.forward_kinematics(q)


def test_fk_command_refuses_huge_legs_in_one_line(capsys):
    status, out, err = run(capsys, "fk", "1e300", "1e300", "1e300", *HOME_LEGS[3:], "0")
    assert status == 1 and out == ""
    assert err.startswith("vgtarm: error: q: s1 = 1e+300 m is outside the accepted range [0, 1.76] m")
    assert err.count("\n") == 1


# -- negative numbers in exponent form -------------------------------------------------------------


@pytest.mark.parametrize("text", ["-1e-3", "-1E-3", "-2.5e-2", "-.5e-1", "-3.e-2"])
def test_fk_takes_negative_numbers_in_exponent_form(capsys, text):
    status, out, err = run(capsys, "fk", *HOME_LEGS, text)
    assert status == 0, err
    assert f"psi3 = {float(text):.10g} rad" in out


def test_negative_exponent_values_with_a_plus_sign(capsys):
    status, out, err = run(capsys, "fk", *HOME_LEGS, "-1E+2")
    assert status == 0, err
    assert "psi3 = -100 rad" in out
    status, _, err = run(capsys, "fk", *HOME_LEGS, "-1E+4")
    assert status == 1
    assert "psi3 = -10000.0 rad is outside the accepted range" in err and err.count("\n") == 1


@pytest.mark.parametrize("text", ["-inf", "-nan"])
def test_negative_non_numbers_reach_the_finite_check(capsys, text):
    status, _, err = run(capsys, "fk", *HOME_LEGS, text)
    assert status == 1 and "q must be finite" in err and err.count("\n") == 1


def test_options_take_negative_exponent_values_too(capsys):
    args = build_parser().parse_args(["simulate", "--case", "1", "--kp", "-1e-3"])
    assert args.kp == "-1e-3"  # parsed as the value (the gains' check then refuses it with one line)
    with pytest.raises(SystemExit):  # a value, refused by the option's declaration (>= 0), not taken for a flag
        build_parser().parse_args(["simulate", "--case", "1", "--velocity-noise", "-1e-3"])
    assert "argument --velocity-noise: expected a standard deviation >= 0" in capsys.readouterr().err


# -- sample spacing and non-finite rates -----------------------------------------------------------


def test_ik_command_refuses_rows_closer_than_a_microsecond(capsys, tmp_path):
    path_file = tmp_path / "p.csv"
    path_file.write_text("t,x,y,z\n0,0,0,0.66\n1e-300,0,0,0.66\n")
    out_file = tmp_path / "q.csv"
    status, _, err = run(capsys, "ik", "--path", str(path_file), "-o", str(out_file))
    assert status == 1 and err.count("\n") == 1
    assert "1e-06 s" in err and "line 3" in err
    assert not out_file.exists()


def test_a_joint_reference_refuses_sub_microsecond_periods(short_ik):
    t = np.arange(len(short_ik.t)) * 1e-300
    with pytest.raises(InputError, match="at least 1e-06 s expected"):
        JointReference(t, short_ik.q, short_ik.qd, short_ik.qdd)


def test_non_finite_rates_make_the_result_fail(robot, monkeypatch):
    """Rates that overflow are never "solved and verified", and the CLI writes nothing."""

    def overflowing(q, dt):
        qd = np.zeros_like(q)
        qd[1, 2] = np.inf
        return qd, np.full_like(q, np.nan)

    monkeypatch.setattr(rate_modes, "finite_difference", overflowing)
    result = robot.inverse_kinematics(paths.case1(duration=0.005), rates="finite_difference")
    assert not result.success
    assert "not finite" in result.message and "sample 0" in result.message
    assert result.samples.success.all()  # every point is solved: only the rates are wrong


# -- a reference solved for another robot ----------------------------------------------------------


@pytest.fixture(scope="module")
def other_robot(robot):
    p = robot.parameters
    return robot.with_parameters(dataclasses.replace(p, name="longer twist", h1=p.h1 + 0.047))


def test_ik_results_record_the_robot(robot, other_robot, short_ik):
    assert short_ik.robot_name == robot.parameters.name and short_ik.robot is robot
    assert short_ik.robot_fingerprint == robot.fingerprint
    assert robot.with_parameters(robot.parameters).fingerprint == robot.fingerprint
    assert other_robot.fingerprint != robot.fingerprint
    scaled = robot.with_parameters(robot.parameters.scaled(mass=2.0))
    assert scaled.fingerprint != robot.fingerprint  # the whole parameter vector counts


def test_simulating_another_robots_reference_is_refused(robot, other_robot, cfc):
    ik = other_robot.inverse_kinematics(paths.case1(duration=0.01))
    gap = np.linalg.norm(robot.tip_position(ik.q) - ik.position, axis=1).max()
    assert gap > 0.04  # the plant's tip is centimetres off the path the joints were solved for
    with pytest.raises(InputError) as info:
        simulate(robot, ik, cfc)
    message = one_line(info.value)
    assert f"{gap * 1e3:.3g} mm" in message
    assert f"solved for robot 'longer twist' ({other_robot.fingerprint})" in message
    assert f"simulating robot {robot.parameters.name!r} ({robot.fingerprint})" in message


def test_the_plants_own_reference_passes_the_check(robot, short_ik, cfc):
    gap = np.linalg.norm(robot.tip_position(short_ik.q) - short_ik.position, axis=1).max()
    assert gap < REFERENCE_TIP_TOLERANCE
    result = simulate(robot, short_ik, cfc)
    assert result.success
    np.testing.assert_array_equal(result.tip_desired, robot.tip_position(short_ik.q))


def test_a_reference_cut_to_a_duration_keeps_its_tip_and_robot(robot):
    from vgtarm.experiment.cases import joint_reference

    reference = joint_reference(robot, 1, duration=0.005)
    assert reference.tip is not None and reference.tip.shape == (len(reference.t), 3)
    assert reference.robot_fingerprint == robot.fingerprint


@pytest.mark.parametrize("reference", [pathlib.Path("ik.csv"), "ik.csv", None, paths.case1(duration=0.01)])
def test_a_reference_of_the_wrong_type_is_one_line(robot, cfc, reference):
    with pytest.raises(InputError, match="expected an IK result or a JointReference") as info:
        simulate(robot, reference, cfc)
    one_line(info.value)


# -- the initial state and partial results ---------------------------------------------------------


@pytest.mark.parametrize(
    ("state", "error", "match"),
    [
        ("q0 nan", InputError, r"initial_state q0\[0\] = nan: expected a finite number"),
        ("qd0 inf", InputError, r"initial_state qd0\[6\] = inf"),
        ("short", InputError, r"initial_state q0: expected shape \(7,\), got \(6,\)"),
        ("text", InputError, "expected a pair"),
        ("far", InputError, "initial_state q0: s1 = 5.0 m is outside the accepted range"),
        ("unassemblable", AssemblyError, "initial_state q0: module 1 cannot be assembled"),
        ("qd0 huge", InputError, r"initial_state qd0: psi3 = 1e\+300 rad/s is outside the accepted range"),
        ("q0 complex", InputError, r"initial_state q0 must be real numbers; .*\(0\.25\+1j\) is complex"),
        ("qd0 None", InputError, r"initial_state qd0 must be real numbers; .* = None is not a number"),
    ],
)
def test_a_bad_initial_state_is_an_input_error_not_a_divergence(robot, short_ik, cfc, state, error, match):
    q0, qd0 = short_ik.q[0].copy(), np.zeros(7)
    value: object = (q0, qd0)
    if state == "q0 nan":
        q0[0] = np.nan
    elif state == "qd0 inf":
        qd0[6] = np.inf
    elif state == "short":
        value = (q0[:6], qd0)
    elif state == "text":
        value = "rest"
    elif state == "far":
        q0[:3] = 5.0
    elif state == "qd0 huge":
        qd0[6] = 1e300
    elif state == "q0 complex":
        value = ([0.25 + 1j, *q0[1:]], qd0)
    elif state == "qd0 None":
        value = (q0, [None] * 7)
    else:
        q0[:3] = (0.22, 0.22, 0.46)
    with pytest.raises(error, match=match) as info:
        simulate(robot, short_ik, cfc, initial_state=value)
    one_line(info.value)


def test_a_run_that_diverges_at_once_still_summarises_and_saves(robot, short_ik, cfc, tmp_path):
    """Rates of 1000 m/s (inside the accepted range; 1e300 is refused before the run) leave the
    limits within the first period."""
    with pytest.raises(SimulationError) as info:
        simulate(robot, short_ik, cfc, initial_state=(short_ik.q[0], np.full(7, 1e3)))
    partial = info.value.result
    assert isinstance(partial, SimulationResult) and not partial.success
    summary = partial.summary()
    assert summary["samples_completed"] >= 1 and summary["success"] is False
    partial.save(tmp_path / "run")
    assert SimulationResult.load(tmp_path / "run").summary()["success"] is False


def test_a_record_without_any_sample_summarises(short_ik, tmp_path):
    n = len(short_ik.t)
    nan3, nan7 = np.full((n, 3), np.nan), np.full((n, 7), np.nan)
    empty = SimulationResult(
        t=short_ik.t,
        tip_desired=short_ik.position,
        tip=nan3,
        tip_error=np.full(n, np.nan),
        q_desired=short_ik.q,
        qd_desired=short_ik.qd,
        q=nan7,
        qd=nan7,
        effort=nan7,
        f_ext=nan3,
        mode=np.full(n, MODE_NOT_RUN, dtype=np.int8),
        activations=(),
        success=False,
        message="diverged at t = 0 s",
        wall_time_s=0.0,
        ga_time_s=0.0,
    )
    summary = empty.summary()  # no "All-NaN slice encountered"
    assert summary["samples_completed"] == 0
    assert summary["max_tip_error_m"] is None and summary["time_of_max_tip_error_s"] is None
    assert summary["peak_force_n"] is None and summary["rms_force_n"] is None
    empty.save(tmp_path / "empty")
    assert (tmp_path / "empty" / "summary.json").is_file()


def test_nan_samples_do_not_hide_the_known_figures(short_ik):
    """A record with NaN after a failure summarises the samples before it (checked by hand)."""
    n = len(short_ik.t)
    error = np.full(n, np.nan)
    error[:3] = (1e-4, 3e-4, 2e-4)
    effort = np.full((n, 7), np.nan)
    effort[:3] = 1.0
    effort[1, 0] = -4.0
    mode = np.full(n, MODE_NOT_RUN, dtype=np.int8)
    mode[:3] = 0
    record = SimulationResult(
        t=short_ik.t,
        tip_desired=short_ik.position,
        tip=short_ik.position,
        tip_error=error,
        q_desired=short_ik.q,
        qd_desired=short_ik.qd,
        q=short_ik.q,
        qd=short_ik.qd,
        effort=effort,
        f_ext=np.zeros((n, 3)),
        mode=mode,
        activations=(),
        success=False,
        message="diverged",
        wall_time_s=1.0,
        ga_time_s=0.0,
    )
    summary = record.summary()
    assert summary["max_tip_error_m"] == 3e-4
    assert summary["time_of_max_tip_error_s"] == pytest.approx(short_ik.t[1])
    assert summary["rms_tip_error_m"] == pytest.approx(math.sqrt((1e-8 + 9e-8 + 4e-8) / 3))
    assert summary["peak_force_n"] == 4.0


# -- wrong types and values given to the API -------------------------------------------------------


@pytest.mark.parametrize("value", [math.nan, math.inf, 0.0, -0.01, 1.0, "0.05", None])
def test_limit_tolerance_must_be_a_small_positive_distance(robot, short_ik, cfc, value):
    with pytest.raises(InputError, match=r"limit_tolerance = .*expected a distance in \(0, 0.22\]") as info:
        simulate(robot, short_ik, cfc, limit_tolerance=value)
    one_line(info.value)


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"threshold": "1"}, r"^threshold = '1': expected a finite number > 0 \(m\)$"),
        ({"threshold": None}, "threshold = None"),
        ({"threshold": math.nan}, "threshold = nan"),
        ({"kp_bounds": "ab"}, "kp_bounds = 'ab'"),
        ({"kv_bounds": (0, 1, 2)}, r"kv_bounds = \(0, 1, 2\)"),
        ({"kp_bounds": (0.0, 4000.0)}, r"fixed gains Kp\[0, 0\] = 5000 is outside kp_bounds = \[0, 4000\]"),
        ({"kv_bounds": (10.0, 600.0)}, r"fixed gains Kv\[0, 1\] = 0 is outside kv_bounds = \[10, 600\]"),
        ({"horizon": 10**20}, r"^horizon = 100000000000000000000: expected a whole number from 1 to 10,000 \("),
        ({"horizon": True}, "horizon = True"),
        ({"ga": "fast"}, "ga = 'fast': expected a vgtarm.ga.GAOptions"),
        ({"prediction": []}, r"prediction = \[\]"),
        ({"exact_above": "1"}, "exact_above = '1'"),
    ],
)
def test_switching_control_arguments(options, match):
    with pytest.raises(InputError, match=match) as info:
        SwitchingControl.with_gains(5000.0, 300.0, **options)
    one_line(info.value)


def test_gains_and_controllers_refuse_wrong_types():
    with pytest.raises(InputError, match="expected Gains"):
        ComputedForceControl("5000")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="expected Gains"):
        SwitchingControl(None)  # type: ignore[arg-type]
    for value in ("5000", None, 10**400):
        with pytest.raises(InputError, match="Kp must be a number"):
            Gains.of(value, 300.0)
    with pytest.raises(InputError, match=r"Kv must be finite, got Kv\[0, 0\] = nan"):
        Gains.of(1.0, math.nan)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda c: ga.minimize(c, "ab", [1.0, 1.0], seed=0), "^lower = 'ab': expected an array of numbers$"),
        (
            lambda c: ga.minimize(c, ["0", "0"], [1.0, 1.0], seed=0),
            r"^lower = \['0', '0'\]: expected an array of numbers$",
        ),
        (lambda c: ga.minimize(c, [0.0, 0.0], None, seed=0), "^upper = None: expected an array of numbers$"),
        (lambda c: ga.minimize(c, [0.0, 0.0], [1.0, 1.0], seed=0, initial="ab"), "^initial = 'ab': expected an array"),
        (lambda c: ga.minimize(lambda x: "cost", [0.0], [1.0], seed=0), "`cost` must return"),
        (lambda c: ga.minimize(c, [0.0], [1.0], seed="0"), "^seed = '0': expected a whole number from 0 to 2"),
        (lambda c: ga.encode("a", [0.0], [1.0]), "^values = 'a': expected an array of numbers$"),
        (
            lambda c: ga.GAOptions(population_size=10**12),
            "^population_size = 1000000000000: expected a whole number from 2 to 1,000,000$",
        ),
    ],
)
def test_ga_arguments(call, match):
    with pytest.raises(InputError, match=match) as info:
        call(lambda x: (x**2).sum(axis=1))
    one_line(info.value)


@pytest.mark.parametrize(
    ("keyword", "value", "match"),
    [
        ("controller_model", "model", "controller_model = 'model'"),
        ("external_force", "cutting", "external_force = 'cutting'"),
        ("integrator", [], r"integrator = \[\]: expected one of \['euler'"),
        ("plant_engine", None, "plant_engine = None"),
        ("metadata", 3, "metadata = 3"),
        ("progress", 3, "progress = 3"),
        ("transient_s", "0.2", "transient_s = '0.2'"),
        ("encoder_resolution", "1e-6", "encoder_resolution = '1e-6': expected an encoder step >= 0 \\(m\\)"),
        ("encoder_resolution", 1e300, "encoder_resolution = 1e[+]300: expected an encoder step of at most 0.01 m"),
        ("velocity_noise", math.nan, "velocity_noise = nan"),
    ],
)
def test_simulate_arguments(robot, short_ik, cfc, keyword, value, match):
    with pytest.raises(InputError, match=match) as info:
        simulate(robot, short_ik, cfc, **{keyword: value})
    one_line(info.value)


def test_simulate_refuses_a_plant_that_is_not_a_robot(short_ik, cfc):
    with pytest.raises(InputError, match="plant = 'robot': expected a vgtarm.Robot"):
        simulate("robot", short_ik, cfc)  # type: ignore[arg-type]


def _bodies_scaled(parameters, mass: float = 1.0, inertia: float = 1.0):
    """``parameters`` with every body's mass and inertia multiplied (without ``scaled``'s own check)."""
    bodies = tuple(
        dataclasses.replace(b, mass=b.mass * mass, inertia=tuple(tuple(x * inertia for x in r) for r in b.inertia))
        for b in parameters.bodies
    )
    return dataclasses.replace(parameters, bodies=bodies)


@pytest.mark.parametrize(
    ("mass", "inertia", "friction", "match"),
    [
        (1e4, 1.0, 1.0, r"its mass is 1e\+04 times the plant's"),
        (1e-4, 1.0, 1.0, r"its mass is 0\.0001 times the plant's"),
        (1.0, 2e3, 1.0, r"its inertia is 2e\+03 times the plant's"),
        (1.0, 1.0, 1e-5, r"its friction is 1e-05 times the plant's"),
    ],
)
def test_a_controller_model_far_from_the_plant_names_the_ratio_and_the_range(
    robot, short_ik, cfc, mass, inertia, friction, match
):
    """Issue 20, item 9: a model a thousand times off is no model of the plant; the line says the
    ratio and the accepted range, never "not finite"."""
    model = _bodies_scaled(robot.parameters, mass, inertia)
    model = dataclasses.replace(model, viscous=tuple(c * friction for c in model.viscous))
    for given in (model, robot.with_parameters(model)):
        with pytest.raises(
            InputError, match=rf"^controller_model: {match} .*expected a ratio in \[0\.001, 1000\]"
        ) as info:
            simulate(robot, short_ik, cfc, controller_model=given)
        one_line(info.value)


def test_controller_models_at_the_ends_of_the_range_run(robot, short_ik, cfc):
    """Accepted, they run (a model a thousand times too heavy wrecks the run: a divergence, not a refusal)."""
    for factor in (1e-3, 1e3):
        try:
            result = simulate(robot, short_ik, cfc, controller_model=_bodies_scaled(robot.parameters, factor, factor))
        except SimulationError as error:
            result = error.result
        assert result.q.shape == short_ik.q.shape


def test_model_mass_far_below_the_plants_is_refused_with_the_range(capsys):
    status, out, err = run(capsys, "simulate", "--case", "1", "--duration", "0.01", "--model-mass", "1e-300", "-q")
    assert status == 1 and err.count("\n") == 1
    assert "1e-300" in err and "[0.001, 1000]" in err and "finite" not in err


@pytest.mark.parametrize("value", ["1e308", "1e10"])
def test_model_mass_far_above_the_plants_is_refused_with_the_range(capsys, value):
    status, out, err = run(capsys, "simulate", "--case", "1", "--duration", "0.01", "--model-mass", value, "-q")
    assert status == 1 and err.count("\n") == 1
    assert repr(float(value)) in err and "[0.001, 1000]" in err and "finite" not in err


def test_robot_methods_refuse_wrong_types(robot):
    with pytest.raises(InputError, match="expected RobotParameters"):
        vgtarm.Robot("reference")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="expected RobotParameters"):
        robot.with_parameters(None)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="margin = 'x'"):
        robot.is_assemblable(robot.parameters.home, margin="x")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="no compiled function named 'nope'"):
        robot.evaluate("nope", {}, 1)
    with pytest.raises(InputError, match="q must be an array of numbers"):
        robot.tip_position("home")


def test_inverse_kinematics_arguments(robot):
    from vgtarm.ik import inverse_kinematics

    path = paths.case1(duration=0.005)
    with pytest.raises(InputError, match="robot must be a vgtarm.Robot"):
        inverse_kinematics("robot", path)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="initial_guess .* is outside the accepted joint range"):
        robot.inverse_kinematics(path, initial_guess=[1e20] * 7)


def test_case_arguments(robot):
    from vgtarm.experiment.cases import joint_reference, run_case

    with pytest.raises(InputError, match="duration = 'x'"):
        joint_reference(robot, 1, duration="x")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="ga = '3'"):
        run_case(robot, 1, controller="scm", ga="3", reference=joint_reference(robot, 1, duration=0.003))


# -- overflow --------------------------------------------------------------------------------------


def test_coordinates_of_1e300_are_one_line(robot, capsys, tmp_path):
    """Path points of 1e300 m (API and command line) end in one line, not an OverflowError."""
    with pytest.raises(PathError, match=r"sample 0 .* expected coordinates within \+-1000 m") as info:
        robot.inverse_kinematics(paths.case1(x0=1e300, duration=0.005))
    one_line(info.value)
    path_file = tmp_path / "far.csv"
    path_file.write_text("t,x,y,z\n0,1e300,0,0.66\n1,0,0,0.66\n")
    status, _, err = run(capsys, "ik", "--path", str(path_file))
    assert status == 1 and err.count("\n") == 1 and "1e+300" in err


def test_the_simulate_command_turns_a_huge_horizon_into_one_line(capsys):
    with pytest.raises(SystemExit) as exit_:  # argparse's one line, from the option's declaration
        argv = ["simulate", "--case", "1", "--duration", "0.003", "-q", "--controller", "scm", "--horizon", str(10**20)]
        run(capsys, *argv)
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and err.strip().splitlines()[-1].endswith(
        "argument --horizon: expected a whole number from 1 to 10,000 (control periods; SCM), got 100000000000000000000"
    )


def test_mujoco_check_refuses_an_absurd_state_count():
    from vgtarm.mujoco_bridge.check import cross_validate

    robot = vgtarm.load_robot()
    with pytest.raises(
        InputError, match=r"^n = 100000000000000000000: expected a whole number from 1 to 1,000,000 \(states\)$"
    ):
        cross_validate(robot, n=10**20)


def test_every_error_here_is_a_vgtarm_error():
    """The hierarchy the tests above rely on: every refusal is a VgtarmError and a ValueError."""
    for cls in (InputError, AssemblyError, PathError):
        assert issubclass(cls, VgtarmError) and issubclass(cls, ValueError)


def test_other_public_functions_refuse_wrong_types(robot, tmp_path):
    from vgtarm.ik import write_csv

    with pytest.raises(InputError, match="expected an IKResult"):
        write_csv(pathlib.Path("q.csv"), tmp_path / "out.csv")  # type: ignore[arg-type]
    assert not (tmp_path / "out.csv").exists()
    for value in ("2", math.nan, 0, True, 10**400):
        with pytest.raises(vgtarm.ConfigError, match="scaled: mass = .*expected a (finite )?factor"):
            robot.parameters.scaled(mass=value)  # type: ignore[arg-type]
    for value in ("0.001", b"1", None):
        with pytest.raises(PathError, match=r"^dt = .*: expected a finite number >= 1e-06 \(s\)$"):
            paths.case1(dt=value)  # type: ignore[arg-type]
