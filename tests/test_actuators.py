"""Actuators: the robot file's [actuators] table, its refusals, the force-speed limits, and the
saturation in the closed loop, against an analytic motor, the NumPy loop and a replay of the
applied efforts."""

from __future__ import annotations

import dataclasses
import math
import tomllib
import warnings
from importlib import resources

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import vgtarm
from vgtarm.control import ComputedForceControl
from vgtarm.errors import ConfigError
from vgtarm.model.actuators import Actuator, Actuators, effort_bounds
from vgtarm.model.compiled import InterpretedBackend, build_functions
from vgtarm.model.robot import robot_from_dict
from vgtarm.model.stack.description import stack_from_dict, stack_from_parameters, stack_to_toml
from vgtarm.simulation import JointReference, simulate

from .conftest import assert_close

CFC = ComputedForceControl.with_gains(5000.0, 300.0)
LEGS = {"force": 60.0, "speed": 0.05}


def _reference_file() -> dict:
    text = resources.files("vgtarm.model.data").joinpath("reference_robot.toml").read_text("utf-8")
    return tomllib.loads(text)


def _with(robot: vgtarm.Robot, **by_name: Actuator | None) -> vgtarm.Robot:
    """``robot`` with actuators built in Python (no file check: a limit below the home hold is allowed)."""
    joints = tuple(by_name.get(name) for name in robot.joint_names)
    actuators = Actuators(names=robot.joint_names, joints=joints)
    return robot.with_parameters(dataclasses.replace(robot.parameters, actuators=actuators))


# -- the file ------------------------------------------------------------------------------------


def test_groups_and_joint_entries_merge_key_by_key():
    data = _reference_file()
    data["actuators"] = {
        "legs": LEGS,
        "twists": {"force": 2.0, "speed": 3.0},
        "p1": {"force": 90.0, "acceleration": 1.5, "force_speed": True},
    }
    robot = robot_from_dict(data, source="arm.toml")
    a = robot.actuators
    assert a is not None and a.names == robot.joint_names
    np.testing.assert_array_equal(a.force, [60, 60, 90, 60, 60, 60, 2])
    np.testing.assert_array_equal(a.speed, [0.05] * 6 + [3.0])
    np.testing.assert_array_equal(a.acceleration, [math.inf, math.inf, 1.5] + [math.inf] * 4)
    np.testing.assert_array_equal(a.force_speed, [False, False, True, False, False, False, False])
    assert vgtarm.load_robot().actuators is None  # the paper's robot: none


def test_a_joint_no_table_covers_has_no_limits():
    data = _reference_file()
    data["actuators"] = {"s1": LEGS}
    a = robot_from_dict(data, source="arm.toml").actuators
    assert a is not None
    assert list(a.limited) == [True] + [False] * 6
    assert np.isinf(a.force[1:]).all()
    lower, upper = a.bounds(np.full(7, 0.3))
    assert np.isinf(upper[1:]).all() and np.isneginf(lower[1:]).all()


def test_a_stack_writes_its_actuators_back_and_reads_them_the_same():
    data = _reference_file()
    data["actuators"] = {"legs": LEGS, "p2": {"force": 80.0, "force_speed": True, "acceleration": 2.0}}
    stack = stack_from_parameters(robot_from_dict(data, source="arm.toml").parameters)
    again = stack_from_dict(tomllib.loads(stack_to_toml(stack)), source="again.toml")
    assert again.actuators == stack.actuators
    assert again.actuators is not None and again.actuators.force_speed[5]


@pytest.mark.parametrize(
    ("table", "message"),
    [
        (
            {"legs": {"force": 0.0, "speed": 0.05}},
            "field 'actuators.legs.force' (joint s1) = 0.0: expected a number in (0, 1e+09] (N)",
        ),
        ({"legs": {"force": -5.0, "speed": 0.05}}, "field 'actuators.legs.force' (joint s1) = -5.0"),
        ({"s1": {"force": float("nan"), "speed": 0.05}}, "field 'actuators.s1.force' = nan"),
        (
            {"legs": {"force": 60.0, "speed": 0.0}},
            "field 'actuators.legs.speed' (joint s1) = 0.0: expected a number in (0, 1e+06] (m/s)",
        ),
        (
            {"twists": {"force": 1.0, "speed": 1.0, "acceleration": -1.0}},
            "'actuators.twists.acceleration' (joint psi3) = -1.0",
        ),
        ({"legs": LEGS, "s1": {"force": 10.0}}, "field 'actuators.s1.force' = 10.0: expected at least 31.1412 N"),
        ({"legs": {"force": 20.0, "speed": 0.05}}, "field 'actuators.legs.force' = 20.0: expected at least 31.1412 N"),
        ({"s1": {"force": 60.0}}, "missing key 'actuators.s1.speed'"),
        ({"s9": LEGS}, "unknown key 'actuators.s9'"),
        ({"s1": {**LEGS, "stall": 1.0}}, "unknown key 'actuators.s1.stall'"),
        ({"s1": {**LEGS, "force_speed": 1}}, "field 'actuators.s1.force_speed' = 1: expected True or False"),
        ({"s1": 60.0}, "field 'actuators.s1' = 60.0"),
    ],
)
def test_a_bad_limit_is_refused_in_one_line_naming_the_field(table, message):
    data = _reference_file()
    data["actuators"] = table
    with pytest.raises(ConfigError) as caught:
        robot_from_dict(data, source="arm.toml")
    text = str(caught.value)
    assert "\n" not in text and text.startswith("arm.toml: ") and message in text, text


def test_the_home_hold_is_the_gravity_the_model_computes(robot):
    """The refusal's threshold is the inverse dynamics at rest at home: a limit just above it loads."""
    hold = robot.inverse_dynamics(robot.parameters.home, np.zeros(7), np.zeros(7))
    data = _reference_file()
    data["actuators"] = {"s2": {"force": float(abs(hold[3])) * (1 + 1e-9), "speed": 0.05}}
    assert robot_from_dict(data, source="arm.toml").actuators is not None
    data["actuators"] = {"s2": {"force": float(abs(hold[3])) * (1 - 1e-9), "speed": 0.05}}
    with pytest.raises(ConfigError, match="actuators.s2.force"):
        robot_from_dict(data, source="arm.toml")


# -- the limits ----------------------------------------------------------------------------------


def test_the_force_speed_line_is_a_voltage_limited_motor():
    """The motor's current range at speed ``v``: ``(+-V - K_e v) / R`` within ``+-I_max``; with
    ``F_s = K_t V / R = K_t I_max`` and ``v_max = V / K_e`` that is the line of the module."""
    Fs, vmax = 60.0, 0.05
    a = Actuators(names=("s1",), joints=(Actuator(force=Fs, speed=vmax, force_speed=True),))
    v = np.linspace(-0.12, 0.12, 241)[:, None]
    lower, upper = a.bounds(v)
    Kt, R, V = 2.0, 1.5, 45.0  # N/A, ohm, volt: F_s = Kt V / R = 60 N
    Ke = V / vmax
    current_high = np.clip((V - Ke * v) / R, -V / R, V / R)
    current_low = np.clip((-V - Ke * v) / R, -V / R, V / R)
    assert_close(upper, Kt * current_high, rtol=1e-12, atol=1e-12, what="upper")
    assert_close(lower, Kt * current_low, rtol=1e-12, atol=1e-12, what="lower")
    box = Actuators(names=("s1",), joints=(Actuator(force=Fs, speed=vmax),))
    assert (box.bounds(v)[1] == Fs).all() and (box.bounds(v)[0] == -Fs).all()


def test_saturate_and_utilisation_agree():
    rng = np.random.default_rng(4)
    a = Actuators(
        names=("s1", "v1", "psi2"),
        joints=(Actuator(60.0, 0.05, force_speed=True), Actuator(40.0, 0.1), None),
    )
    F = rng.normal(scale=80.0, size=(500, 3))
    v = rng.normal(scale=0.05, size=(500, 3))
    clipped = a.saturate(F, v)
    assert (a.utilisation(clipped, v)[:, :2] <= 1 + 1e-15).all()
    inside = a.utilisation(F, v)[:, :2] <= 1
    np.testing.assert_array_equal(clipped[:, :2][inside], F[:, :2][inside])
    np.testing.assert_array_equal(clipped[:, 2], F[:, 2])  # no actuator: untouched
    lower, upper = effort_bounds(a.force, a.speed, a.force_speed, v)
    np.testing.assert_array_equal(clipped, np.minimum(np.maximum(F, lower), upper))


# -- the closed loop -----------------------------------------------------------------------------


def _spin_reference(robot: vgtarm.Robot, duration: float, acceleration: float) -> JointReference:
    """Legs held at home, the twist asked to spin up at ``acceleration`` (rad/s^2)."""
    t = np.arange(0.0, duration + 1e-12, 1e-3)
    q = np.tile(robot.parameters.home, (len(t), 1))
    qd, qdd = np.zeros_like(q), np.zeros_like(q)
    q[:, -1] = 0.5 * acceleration * t**2
    qd[:, -1] = acceleration * t
    qdd[:, -1] = acceleration
    return JointReference(t, q, qd, qdd)


def test_a_saturated_twist_spins_up_as_a_motor_does(robot):
    """The end-effector is symmetric about the twist axis with its centre of mass on it, so with the
    legs held the twist obeys ``I w' = tau`` alone (I = the effector's Izz). Asked for far more than
    its motor gives, the controller clips its command to the peak torque ``tau_s`` and the motor
    delivers ``tau_s (1 - w / w_max)`` at every instant (its back-EMF, in the plant's every RK4
    stage): the speed of a DC motor, ``w(t) = w_max (1 - exp(-t / T))`` with ``T = I w_max / tau_s``
    (RK4's error at 1 ms on T = 0.35 s: below 1e-10 relative)."""
    tau_s, w_max = 0.05, 20.0
    plant = _with(robot, psi3=Actuator(force=tau_s, speed=w_max, force_speed=True))
    run = simulate(plant, _spin_reference(plant, 0.3, 2000.0), CFC, integrator="rk4")
    inertia = robot.parameters.bodies[2].inertia[2][2]
    expected = w_max * (1.0 - np.exp(-run.t * tau_s / (inertia * w_max)))
    assert_close(run.qd[:, -1], expected, rtol=1e-9, atol=1e-12, what="twist speed")
    np.testing.assert_array_equal(run.effort[:, -1], tau_s)  # the command, clipped to the peak
    assert np.abs(run.q[:, :-1] - robot.parameters.home[:-1]).max() < 1e-12  # the legs never moved
    assert run.summary()["actuator_time_at_limit_s"] == {"psi3": pytest.approx(0.301)}
    assert run.summary()["actuator_peak_utilisation"]["psi3"] == 1.0


def test_a_stiff_force_speed_line_is_integrated_stably_when_the_step_is_short_enough(robot):
    """Legs on 60 N, 0.05 m/s lines: a damping of 1200 N s/m on an arm whose lightest mode is 0.42 kg,
    so h lambda = 2.9 at Euler's 1 ms: the run is warned of, and it chatters (the effort jumps
    between samples); with two substeps (h lambda = 1.4) it does not, and it agrees with RK4."""
    lines = {name: Actuator(force=60.0, speed=0.05, force_speed=True) for name in robot.joint_names[:6]}
    plant = _with(robot, **lines)
    ref = vgtarm.inverse_kinematics(plant, vgtarm.paths.case1(duration=2.0))
    with pytest.warns(RuntimeWarning, match=r"too stiff for euler steps of 0.001 s: h lambda = 2.88 > 2"):
        coarse = simulate(plant, ref, CFC)
    window = (coarse.t > 1.55) & (coarse.t < 1.7)
    assert np.abs(np.diff(coarse.effort[window, 0])).max() > 2.0  # N from one millisecond to the next
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fine = simulate(plant, ref, CFC, substeps=2)
        reference = simulate(plant, ref, CFC, integrator="rk4", substeps=4)
    assert np.abs(np.diff(fine.effort[window, 0])).max() < 0.2
    assert abs(fine.summary()["max_tip_error_m"] / reference.summary()["max_tip_error_m"] - 1) < 0.05


def test_the_loop_integrates_the_applied_effort_not_the_command(robot):
    """Replayed with SciPy (the plant's forward dynamics under each sample's recorded effort, held, as
    the motors' force-speed lines deliver it at every instant), a run whose legs saturate lands on
    the loop's states: the plant got the clipped effort, through the lines."""
    plant = _with(robot, **{name: Actuator(force=45.0, speed=0.05, force_speed=True) for name in robot.joint_names[:6]})
    ref = vgtarm.inverse_kinematics(plant, vgtarm.paths.case1(duration=0.4))
    run = simulate(plant, ref, CFC, integrator="rk4", substeps=4)
    assert run.summary()["actuator_time_at_limit_s"]["v1"] > 0.05
    n = plant.n_joints
    for k in (50, 150, 300):

        def rhs(_t, x, F=run.effort[k]):  # the motors deliver the held effort as their lines allow
            delivered = plant.actuators.saturate(F, x[n:])
            return np.concatenate([x[n:], plant.forward_dynamics(x[:n], x[n:], delivered)])

        x0 = np.concatenate([run.q[k], run.qd[k]])
        end = solve_ivp(rhs, (0.0, 1e-3), x0, rtol=1e-12, atol=1e-14).y[:, -1]
        assert_close(end[:n], run.q[k + 1], rtol=0, atol=1e-12, what=f"q at {k + 1}")
        # RK4 across the line's kink (min, max) within a step: a little short of its smooth accuracy
        assert_close(end[n:], run.qd[k + 1], rtol=0, atol=1e-8, what=f"qd at {k + 1}")
        assert (np.abs(run.effort[k]) <= plant.actuators.force).all()  # the controller's clip: the peak


@pytest.mark.parametrize("options", [{}, {"encoder_resolution": 1e-6, "observer": "momentum"}])
def test_the_compiled_loop_saturates_as_its_numpy_twin(robot, options):
    plant = _with(
        robot, **{name: Actuator(force=60.0, speed=0.05, force_speed=name[0] != "s") for name in robot.joint_names[:6]}
    )
    slow = vgtarm.Robot(plant.parameters, InterpretedBackend(build_functions()))
    ref = vgtarm.inverse_kinematics(plant, vgtarm.paths.case1(duration=0.3))
    fast, twin = simulate(plant, ref, CFC, substeps=2, **options), simulate(slow, ref, CFC, substeps=2, **options)
    assert twin.metadata["backend"] == "interpreted"
    for name in ("q", "qd", "effort"):
        assert_close(getattr(fast, name), getattr(twin, name), rtol=1e-9, atol=1e-12, what=name)
    assert fast.summary()["actuator_time_at_limit_s"] == twin.summary()["actuator_time_at_limit_s"]
    assert fast.summary()["actuator_time_at_limit_s"]["v1"] > 0.1


def test_without_actuators_nothing_changes(robot):
    """A robot with an actuator table that never binds runs bit for bit as the robot without one."""
    ref = vgtarm.inverse_kinematics(robot, vgtarm.paths.case1(duration=0.2))
    loose = _with(robot, **{name: Actuator(force=1e6, speed=1e3) for name in robot.joint_names})
    a, b = simulate(robot, ref, CFC), simulate(loose, ref, CFC)
    np.testing.assert_array_equal(a.q, b.q)
    np.testing.assert_array_equal(a.effort, b.effort)
    assert "actuator_peak_utilisation" not in a.summary()
    assert b.summary()["actuator_time_at_limit_s"]["s1"] == 0.0


def test_the_mujoco_plant_saturates_as_ours_and_its_motors_carry_the_peak_force(robot):
    """The MJCF's motors get ``forcerange`` = +-peak force (MuJoCo's own clamp). With peak forces only,
    a saturating run on the MuJoCo plant follows ours to the integrators' agreement (RK4: 1e-9 m, as
    without limits). The force-speed line has no MJCF form: vgtarm applies it before each MuJoCo step,
    at that step's velocity, held over the step where ours acts at every RK4 stage; the two then agree
    to first order in the step (measured 1.1e-5 m at 1 ms, 1.4e-6 m at 8 substeps)."""
    mujoco = pytest.importorskip("mujoco")
    box = {name: Actuator(force=40.0, speed=0.05) for name in robot.joint_names[:6]}
    plant = _with(robot, **box)
    model = mujoco.MjModel.from_xml_string(vgtarm.to_mjcf(plant))
    np.testing.assert_array_equal(model.actuator_forcerange[:6], [[-40.0, 40.0]] * 6)
    assert list(model.actuator_forcelimited) == [1] * 6 + [0]
    ref = vgtarm.inverse_kinematics(plant, vgtarm.paths.case1(duration=0.3))
    ours = simulate(plant, ref, CFC, integrator="rk4")
    theirs = simulate(plant, ref, CFC, integrator="rk4", plant_engine="mujoco")
    np.testing.assert_allclose(theirs.q, ours.q, rtol=0, atol=1e-9)
    assert theirs.summary()["actuator_time_at_limit_s"] == ours.summary()["actuator_time_at_limit_s"]
    assert max(ours.summary()["actuator_time_at_limit_s"].values()) > 0.01
    lines = _with(robot, **{name: Actuator(force=60.0, speed=0.05, force_speed=name[0] != "s") for name in box})
    gaps = []
    for substeps in (1, 8):
        ours = simulate(lines, ref, CFC, integrator="rk4", substeps=substeps)
        theirs = simulate(lines, ref, CFC, integrator="rk4", substeps=substeps, plant_engine="mujoco")
        gaps.append(np.abs(theirs.q - ours.q).max())
    assert gaps[0] < 3e-5 and gaps[1] < gaps[0] / 4  # first order in the step


def test_the_recursive_model_saturates_as_the_symbolic_one(robot):
    """The same arm as a stack on the recursive O(n) model (its own compiled loop functions, the same
    driver): the same clipped run to round-off, the same time at each limit."""
    from vgtarm.model.robot import recursive_robot
    from vgtarm.model.stack.description import stack_from_parameters

    actuators = {name: Actuator(force=60.0, speed=0.05, force_speed=name[0] != "s") for name in robot.joint_names[:6]}
    symbolic = _with(robot, **actuators)
    recursive = recursive_robot(stack_from_parameters(symbolic.parameters))
    ref = vgtarm.inverse_kinematics(symbolic, vgtarm.paths.case1(duration=0.3))
    joint_ref = JointReference(ref.t, ref.q, ref.qd, ref.qdd)
    a, b = simulate(symbolic, joint_ref, CFC, substeps=2), simulate(recursive, joint_ref, CFC, substeps=2)
    assert b.metadata["backend"] == "recursive"
    assert_close(b.q, a.q, rtol=0, atol=1e-14, what="q")
    assert_close(b.effort, a.effort, rtol=1e-10, atol=1e-10, what="effort")
    assert b.summary()["actuator_time_at_limit_s"] == a.summary()["actuator_time_at_limit_s"]


def test_the_exported_controller_clips_as_the_simulation_bit_for_bit(robot, tmp_path):
    """Case 2 under the observer with 1 um encoders, legs on 60 N lines (two substeps: the lines are
    stiff for one Euler step of 1 ms, see the test above): the exported C closed through
    vgtarm's plant gives the simulation's efforts bit for bit, saturated samples included, and its
    export.json records the limits."""
    pytest.importorskip("cffi")
    import json

    from vgtarm.experiment.cases import case_study, joint_reference
    from vgtarm.export import CompiledExport, export_controller, simulate_exported
    from vgtarm.simulation import Scenario

    case = case_study(2)
    actuators = {name: Actuator(force=60.0, speed=0.05, force_speed=name[0] != "s") for name in robot.joint_names[:6]}
    plant = _with(robot, **actuators)
    scenario = Scenario(external_force=case.external_force, observer="momentum", encoder_resolution=1e-6, substeps=2)
    folder = export_controller(plant, tmp_path / "controller", scenario=scenario, kp=case.kp, kv=case.kv).folder
    record = json.loads((folder / "export.json").read_text())
    assert record["effort_max"][:6] == [60.0] * 6 and record["effort_max"][6] is None
    reference = joint_reference(plant, 2, duration=0.5)
    theirs = simulate(plant, reference, case.controller("cfc"), scenario)
    mine = simulate_exported(CompiledExport(folder), plant, reference, scenario)
    assert theirs.summary()["actuator_time_at_limit_s"]["s1"] > 0.0  # its 107 N start is clipped
    np.testing.assert_array_equal(mine.effort, theirs.effort)
    np.testing.assert_array_equal(mine.q, theirs.q)
    np.testing.assert_array_equal(mine.effort_estimate, theirs.effort_estimate)


def test_the_page_s_actuator_table_escapes_what_a_user_named():
    from vgtarm.app.reports.html import actuator_markdown

    assert actuator_markdown([("plain", {"max_tip_error_m": 1e-4})]) == []
    summary = {"actuator_peak_utilisation": {"s1": 0.5, "v1": 1.0}, "actuator_time_at_limit_s": {"s1": 0.0, "v1": 0.25}}
    lines = actuator_markdown([("mine | <script>", summary)])
    assert lines[1] == "## Actuators"
    rows = lines[lines.index("| --- | --- | --- | --- |") + 1 :]
    assert len(rows) == 2 and "<script>" not in "\n".join(lines) and rows[0].startswith("| mine \\| ")
    assert rows[1].endswith("| v1 | 1.000 | 0.250 |")


def test_a_leg_too_weak_to_hold_the_arm_gives_its_peak_and_the_arm_sags_as_the_dynamics_say(robot):
    """s1 needs 31.1 N to hold the arm still at home; limited to 20 N (in Python: a file refuses it),
    the controller asks for more at every period and gets 20 N exactly, and the arm sags: the run's
    states are those of the plant's forward dynamics under the efforts applied (SciPy's solve_ivp,
    period by period from the loop's state), and s1 moves down (the leg shortens under the load)."""
    plant = _with(robot, s1=Actuator(force=20.0, speed=0.05))
    home = robot.parameters.home
    t = np.arange(0.0, 0.3 + 1e-12, 1e-3)
    hold = JointReference(t, np.tile(home, (len(t), 1)), np.zeros((len(t), 7)), np.zeros((len(t), 7)))
    run = simulate(plant, hold, CFC, integrator="rk4", substeps=8)
    np.testing.assert_array_equal(run.effort[:, 0], 20.0)
    assert run.summary()["actuator_time_at_limit_s"]["s1"] == pytest.approx(0.301)
    assert run.q[-1, 0] < home[0] - 1e-3
    n = plant.n_joints
    for k in (0, 100, 250):

        def rhs(_t, x, F=run.effort[k]):  # the motors deliver the held effort as their lines allow
            delivered = plant.actuators.saturate(F, x[n:])
            return np.concatenate([x[n:], plant.forward_dynamics(x[:n], x[n:], delivered)])

        end = solve_ivp(rhs, (0.0, 1e-3), np.concatenate([run.q[k], run.qd[k]]), rtol=1e-12, atol=1e-14).y[:, -1]
        assert_close(end[:n], run.q[k + 1], rtol=0, atol=1e-12, what=f"q at {k + 1}")


def test_the_exported_switching_control_clips_as_the_simulation_bit_for_bit(robot, tmp_path):
    """The paper's switching control on case 2 with 1 um encoders, legs on 60 N (lines on v and p):
    closed through the exported C (its controller clips, its GA predicts with the clip as the
    simulation's does), every effort, state and mode equals simulate's bit for bit; and the exported
    GA built with plain arrays (no vector extensions) gives the simulation's activations on the
    run's own states bit for bit (the lanes' clip is selects, no arithmetic that may differ)."""
    from vgtarm.experiment.cases import case_study, joint_reference
    from vgtarm.export import export_controller, simulate_exported
    from vgtarm.simulation import Scenario

    case = case_study(2)
    actuators = {name: Actuator(force=60.0, speed=0.05, force_speed=name[0] != "s") for name in robot.joint_names[:6]}
    plant = _with(robot, **actuators)
    scm = case.controller("scm", variant="paper")
    scenario = Scenario(external_force=case.external_force, encoder_resolution=1e-6, substeps=2)
    folder = export_controller(plant, tmp_path / "x", scenario=scenario, kp=case.kp, kv=case.kv, switching=scm).folder
    reference = joint_reference(plant, 2, duration=0.25)
    theirs = simulate(plant, reference, scm, scenario)
    mine = simulate_exported(folder, plant, reference, scenario, controller=scm)
    assert len(theirs.activations) > 30 and theirs.summary()["actuator_time_at_limit_s"]["s1"] > 0.05
    np.testing.assert_array_equal(mine.effort, theirs.effort)
    np.testing.assert_array_equal(mine.q, theirs.q)
    np.testing.assert_array_equal(mine.mode, theirs.mode)
    from vgtarm.export.galoop import FLAGS, ExportedGA
    from vgtarm.model.closedloop import ClosedLoopDriver, LoopSettings
    from vgtarm.simulation.engines import compiled_ga
    from vgtarm.simulation.simulator import loop_arrays

    arrays = loop_arrays(plant, plant, reference, initial_state=(reference.q[0], reference.qd[0]))
    settings = LoopSettings(reference.dt, "euler", 1, False, 0.0, 0.0, 0.0, 0.0, saturation=True)  # the GA reads
    # only the saturation of a paper variant's settings
    simulation_ga = compiled_ga(scm, ClosedLoopDriver(plant.backend), plant, arrays, reference.dt, settings)
    ks = [a.sample for a in theirs.activations[:: max(len(theirs.activations) // 4, 1)]][:4]
    rng = np.random.default_rng(2)
    q0 = np.array([theirs.q[k] + rng.normal(scale=1e-6, size=plant.n_joints) for k in ks])
    qd0 = np.array([theirs.qd[k] for k in ks])
    seeds = rng.integers(0, 2**63, size=len(ks))
    horizons = [min(scm.horizon, len(reference.t) - 1 - k) for k in ks]
    inp = arrays.inputs
    rows = np.hstack([inp["q_d"], inp["qd_d"], inp["qdd_d"]])
    exported = ExportedGA(folder, flags=(*FLAGS, "-DVGTC_GA_NO_VECTORS")).run(
        ks, horizons, q0, qd0, rows, inp["tip_d"], seeds
    )
    for i, k in enumerate(ks):
        r = simulation_ga.activate(k, q0[i], qd0[i], int(seeds[i]))
        np.testing.assert_array_equal(exported.genes[i], r.genes)
        assert (exported.best_cost[i], exported.seeded_cost[i]) == (r.best_cost, r.seeded_cost)
