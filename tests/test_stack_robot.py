"""A stack of modules as a first-class robot (issue 13): ``load_robot`` of a stack file, its compiled
functions against the interpreted stack model, computed force control on a case path placed on the
robot, the command line, and the paper's robot as a stack against the reference robot."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import vgtarm
from vgtarm import paths
from vgtarm.app.cli.command import main
from vgtarm.errors import ConfigError
from vgtarm.experiment.cases import PAPER_HOME_TIP, case_path, case_study, joint_reference, path_placement, run_case
from vgtarm.model.stack import StackModel

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
DURATION = 0.2  # s of case 1: keeps the suite fast


@pytest.fixture(scope="module")
def six() -> vgtarm.Robot:
    return vgtarm.load_robot(EXAMPLES / "six_modules.toml")


@pytest.fixture(scope="module")
def six_run(six):
    reference = joint_reference(six, 1, duration=DURATION)
    return reference, run_case(six, 1, reference=reference)


def _configurations(robot: vgtarm.Robot, count: int, seed: int) -> np.ndarray:
    """Random configurations within a fifth of each joint's range around home (all assemblable)."""
    rng = np.random.default_rng(seed)
    span = robot.parameters.upper - robot.parameters.lower
    q = robot.parameters.home + 0.1 * span * rng.uniform(-1.0, 1.0, size=(count, robot.n_joints))
    assert robot.is_assemblable(q).all()
    return q


def test_a_stack_file_loads_as_a_robot_with_its_joints(six):
    assert six.is_stack and six.n_joints == 21 and six.n_modules == 6
    assert six.joint_names[:7] == ("s1", "v1", "p1", "s2", "v2", "p2", "psi3")
    assert six.joint_names[-1] == "psi7" and six.joint_units.count("rad") == 3
    G, h = six.margin_form()
    assert G.shape == (36, 21) and h.shape == (36,)
    assert six.is_assemblable(six.parameters.home)


def test_compiled_functions_equal_the_interpreted_stack_model(six):
    model = StackModel(six.parameters)
    q = _configurations(six, 4, seed=1)
    qd = np.random.default_rng(2).normal(size=q.shape)
    fk = six.forward_kinematics(q)
    jp, jw = six.tip_jacobian(q), six.angular_jacobian(q)
    mass, bias = six.mass_matrix(q), six.bias_forces(q, qd)
    for i in range(len(q)):
        ref = model.forward_kinematics(q[i])
        for got, want in (
            (fk.tip[i], ref.tip),
            (fk.rotation[i], ref.rotation),
            (fk.passive[i], ref.passive),
            (fk.platform_position[i], ref.platform_position),
            (fk.platform_rotation[i], ref.platform_rotation),
        ):
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
        want_jp, want_jw = model.jacobians(q[i])
        np.testing.assert_allclose(jp[i], want_jp, rtol=0, atol=1e-12)
        np.testing.assert_allclose(jw[i], want_jw, rtol=0, atol=1e-12)
        want_m = model.mass_matrix(q[i])
        np.testing.assert_allclose(mass[i], want_m, rtol=0, atol=1e-12 * np.abs(want_m).max())
        want_c = model.bias_forces(q[i], qd[i])
        np.testing.assert_allclose(bias[i], want_c, rtol=0, atol=1e-12 * np.abs(want_c).max())
    # forward dynamics: the generated linear solve against NumPy's Cholesky; inverse of each other
    F = np.random.default_rng(3).normal(size=q.shape)
    qdd = six.forward_dynamics(q, qd, F)
    np.testing.assert_allclose(six.inverse_dynamics(q, qd, qdd), F, rtol=0, atol=1e-8)
    want = model.forward_dynamics(q[0], qd[0], F[0])
    np.testing.assert_allclose(qdd[0], want, rtol=0, atol=1e-9 * np.abs(want).max())


def test_case_paths_are_centred_at_the_home_tip_and_scaled_to_the_reach(six):
    placement = path_placement(six)
    assert placement is not None
    tip = six.tip_position(six.parameters.home)
    assert placement.reach == pytest.approx(np.linalg.norm(tip)) and placement.reach == pytest.approx(1.54)
    assert placement.scale == pytest.approx(1.54 / 0.66)
    original, placed = paths.case1(0.01), case_path(six, 1, 0.01)
    back = PAPER_HOME_TIP + (placed.position - tip) / placement.scale
    np.testing.assert_allclose(back, original.position, atol=1e-12)
    np.testing.assert_allclose(placed.velocity, placement.scale * original.velocity)
    assert path_placement(vgtarm.load_robot()) is None  # the paper's robot: the paths as they are


def test_cfc_tracks_case_1_on_the_six_module_arm_reproducibly(six, six_run):
    reference, result = six_run
    assert result.success and result.q.shape == (len(reference.t), 21)
    summary = result.summary()
    size = 0.06 * path_placement(six).scale  # the path's radius on this arm (m)
    assert summary["max_tip_error_m"] < 1e-2 * size
    assert summary["path_scale"] == pytest.approx(1.54 / 0.66)
    again = run_case(six, 1, reference=reference)
    np.testing.assert_array_equal(again.q, result.q)
    np.testing.assert_array_equal(again.effort, result.effort)


def test_a_stack_run_saves_and_loads_with_its_joint_names(six_run, tmp_path):
    _, result = six_run
    result.save(tmp_path / "run")
    header = (tmp_path / "run" / "timeseries.csv").read_text().split("\n", 1)[0].split(",")
    assert "psi7" in header and "F_psi5" in header
    loaded = type(result).load(tmp_path / "run")
    np.testing.assert_array_equal(loaded.q, result.q)


@pytest.mark.parametrize(("controller", "printed"), [("cfc", "max_tip_error_m"), ("scm", "ga_activations")])
def test_the_simulate_command_runs_a_stack(capsys, controller, printed):
    config = str(EXAMPLES / "six_modules.toml")
    argv = ["simulate", "--config", config, "--case", "1", "--controller", controller, "--duration", "0.05", "-q"]
    status = main(argv)
    out, err = capsys.readouterr()
    assert status == 0, err
    assert "path_centre_m" in out and "path_scale" in out and printed in out


def test_describe_and_fk_commands_take_a_stack(capsys, six):
    config = str(EXAMPLES / "six_modules.toml")
    assert main(["describe", "--config", config]) == 0
    out = capsys.readouterr().out
    assert "psi7" in out and "reach 1.54" in out
    q = [repr(float(v)) for v in six.parameters.home]
    assert main(["fk", "--config", config, *q]) == 0
    out = capsys.readouterr().out
    assert "module 6" in out and "1.54" in out
    assert main(["fk", "--config", config, *q[:7]]) == 1
    err = capsys.readouterr().err
    assert "expected 21 joint values" in err and err.count("\n") == 1


def test_the_planar_module_loads_runs_fk_and_ik_in_its_plane():
    robot = vgtarm.load_robot(EXAMPLES / "planar_module.toml")
    assert robot.n_joints == 3 and robot.joint_names == ("s1", "v1", "p1")
    model = StackModel(robot.parameters)
    q = _configurations(robot, 3, seed=5)
    jp = robot.tip_jacobian(q)
    for i in range(len(q)):
        np.testing.assert_allclose(robot.tip_position(q[i]), model.tip_position(q[i]), rtol=0, atol=1e-15)
        np.testing.assert_allclose(jp[i], model.jacobians(q[i])[0], rtol=0, atol=1e-13)
        # central differences of the compiled tip
        step = 1e-6
        fd = np.stack(
            [
                (robot.tip_position(q[i] + step * e) - robot.tip_position(q[i] - step * e)) / (2 * step)
                for e in np.eye(3)
            ],
            axis=1,
        )
        np.testing.assert_allclose(jp[i], fd, rtol=0, atol=1e-8)
    # its tip stays in the u2-u3 plane: the task is the tip's two coordinates there (tests/test_ik_planar.py)
    tip = robot.tip_position(robot.parameters.home)
    path = paths.waypoints([0.0, 0.2], [tip, tip + [0.0, 0.01, -0.005]], 0.01, blend="cubic", name="line")
    result = robot.inverse_kinematics(path)
    assert result.success and result.task_space == "tip (u2, u3) in its plane"
    np.testing.assert_allclose(robot.tip_position(result.q), path.position, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    ("change", "field"),
    [
        (lambda text: text.split("[[modules]]")[0] + text[text.index("[end_effector]") :], "modules"),
        (lambda text: text.replace("d = 0.1\n", "d = 0.2\n", 1), "module1.d"),
        (lambda text: text.replace("plane = 90.0", 'plane = "ninety"', 1), "module2.plane"),
    ],
)
def test_bad_stack_files_are_refused_in_one_line(tmp_path, change, field):
    text = (EXAMPLES / "six_modules.toml").read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(change(text))
    with pytest.raises(ConfigError) as caught:
        vgtarm.load_robot(bad)
    message = str(caught.value)
    assert field in message and "\n" not in message


def test_the_paper_robot_as_a_stack_gives_the_reference_robots_numbers():
    reference, stack = vgtarm.load_robot(), vgtarm.load_robot(EXAMPLES / "paper_robot.toml")
    assert stack.is_stack and stack.joint_names == reference.joint_names
    q = _configurations(reference, 8, seed=4)
    np.testing.assert_array_equal(stack.tip_position(q), reference.tip_position(q))
    np.testing.assert_array_equal(stack.forward_kinematics(q).rotation, reference.forward_kinematics(q).rotation)
    np.testing.assert_array_equal(stack.mass_matrix(q), reference.mass_matrix(q))
    # a CFC run of case 1 to 1e-12: the stack's generated IK derivatives sum the same terms in
    # another order (the tool offset of the stack), so the reference differs in the last bits
    ref_a = joint_reference(reference, 1, duration=DURATION)
    ref_b = joint_reference(stack, 1, duration=DURATION)
    np.testing.assert_allclose(ref_b.q, ref_a.q, rtol=0, atol=1e-12)
    run_a = run_case(reference, 1, reference=ref_a)
    run_b = run_case(stack, 1, reference=ref_b)
    np.testing.assert_allclose(run_b.q, run_a.q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(run_b.effort, run_a.effort, rtol=0, atol=1e-12 * np.abs(run_a.effort).max())
    np.testing.assert_allclose(run_b.tip_error, run_a.tip_error, rtol=0, atol=1e-12)


def test_the_paper_robot_as_a_stack_equals_the_reference_robot_to_1e_14_in_every_output():
    """Every method of the model, on random assemblable states, relative to the output's scale."""
    reference, stack = vgtarm.load_robot(), vgtarm.load_robot(EXAMPLES / "paper_robot.toml")
    rng = np.random.default_rng(11)
    q = _configurations(reference, 64, seed=12)
    qd, qdd = rng.normal(scale=0.05, size=q.shape), rng.normal(size=q.shape)
    F, f_tip = rng.normal(scale=50.0, size=q.shape), rng.normal(scale=20.0, size=(len(q), 3))
    fk_a, fk_b = reference.forward_kinematics(q), stack.forward_kinematics(q)
    pairs = {
        name: (getattr(fk_a, name), getattr(fk_b, name))
        for name in ("tip", "rotation", "passive", "platform_position", "platform_rotation")
    }
    for name, call in {
        "tip_jacobian": lambda r: r.tip_jacobian(q),
        "angular_jacobian": lambda r: r.angular_jacobian(q),
        "tip_hessian": lambda r: r.tip_hessian(q),
        "com_jacobians": lambda r: np.stack(r.com_jacobians(q)),
        "tip_velocity": lambda r: np.stack(r.tip_velocity(q, qd)),
        "bias_accelerations": lambda r: np.concatenate(
            [np.ravel(a) for a in vars(r.bias_accelerations(q, qd)).values()]
        ),
        "mass_matrix": lambda r: r.mass_matrix(q),
        "bias_forces": lambda r: r.bias_forces(q, qd),
        "forward_dynamics": lambda r: r.forward_dynamics(q, qd, F, f_tip=f_tip),
        "inverse_dynamics": lambda r: r.inverse_dynamics(q, qd, qdd, f_tip=f_tip),
        "energy": lambda r: np.stack(r.energy(q, qd)),
    }.items():
        pairs[name] = (call(reference), call(stack))
    for name, (want, got) in pairs.items():
        assert got.shape == want.shape, name
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-14 * max(np.abs(want).max(), 1.0), err_msg=name)


@pytest.fixture(scope="module")
def six_scm_run(six, six_run):
    reference, _ = six_run
    return run_case(six, 1, controller="scm", reference=reference, seed=3, scm_variant="paper")


def test_switching_control_runs_on_the_six_module_arm_with_2_n_squared_genes(six, six_run, six_scm_run):
    reference, _ = six_run
    n = six.n_joints
    controller = case_study(1).controller("scm", n_joints=n, variant="paper")
    lower, upper = controller.bounds()
    assert lower.shape == upper.shape == (2 * n * n,)
    result = six_scm_run
    assert result.success and result.activations, "case 1's start transient crosses the threshold"
    # seeded with the fixed gains and elitist: the GA is never predicted worse than them
    assert all(a.best_fitness <= a.fixed_gains_fitness for a in result.activations)
    size = 0.06 * path_placement(six).scale
    assert result.summary()["max_tip_error_m"] < 1e-2 * size
    again = run_case(six, 1, controller="scm", reference=reference, seed=3, scm_variant="paper")
    np.testing.assert_array_equal(again.q, result.q)
    other = run_case(six, 1, controller="scm", reference=reference, seed=4, scm_variant="paper")
    assert not np.array_equal(other.q, result.q)


def test_switching_control_with_a_one_step_horizon_is_cfc_on_the_six_module_arm(six, six_run):
    """A one-step prediction does not depend on the gains: the GA keeps the seeded fixed gains
    and the run is computed force control's, bit for bit (as on the paper's robot)."""
    reference, cfc = six_run
    result = run_case(six, 1, controller="scm", reference=reference, horizon=1, scm_variant="paper")
    assert result.activations
    assert all(a.best_fitness == a.fixed_gains_fitness for a in result.activations)
    np.testing.assert_array_equal(result.q, cfc.q)


def test_the_observer_and_the_force_sensor_work_on_the_six_module_arm(six):
    """Case 1 with the cutting force and the disturbance on 21 joints: the momentum observer's
    estimate follows ``J_P^T f`` (which the plant applied one period earlier), and with it, or with
    the force sensor, the error after the transient is a small fraction of plain CFC's."""
    reference = joint_reference(six, 1, duration=0.4)
    plain = run_case(six, 1, reference=reference, external_force=True)
    observed = run_case(six, 1, reference=reference, external_force=True, observer="momentum")
    sensed = run_case(six, 1, reference=reference, external_force=True, force_sensor=True)
    late = reference.t > 0.2
    for run in (observed, sensed):
        assert run.success
        assert run.tip_error[late].max() < 0.05 * plain.tip_error[late].max()
    tau_ext = np.einsum("kij,ki->kj", six.tip_jacobian(observed.q), observed.f_ext)
    estimate = observed.effort_estimate
    assert estimate is not None and estimate.shape == (len(reference.t), six.n_joints)
    # the cutting force turns with the path (slowly) and the disturbance is redrawn every period:
    # compare the estimate with the applied efforts averaged over 50 ms windows after the transient
    window = 50
    start = int(np.argmax(late))
    for k in range(start, len(reference.t) - window, window):
        got = estimate[k + 1 : k + 1 + window].mean(axis=0)
        want = tau_ext[k : k + window].mean(axis=0)
        assert np.linalg.norm(got - want) < 0.1 * np.linalg.norm(want), k


def test_the_report_of_a_stack_names_the_robot_and_the_placement_of_the_paths(six, six_run, six_scm_run):
    from vgtarm.app.reports.reproduce import RunSpec, render_report

    _, cfc = six_run
    runs = {RunSpec(1, "cfc", False, "exact"): cfc, RunSpec(1, "scm", False, "exact"): six_scm_run}
    markdown = render_report(runs, {}, seed=0, integrator="euler", substeps=1, wall_time_s=1.0)
    assert six.parameters.name in markdown
    assert "This robot is not the paper's" in markdown and "(0, 0, 1.54) m" in markdown and "2.333 times" in markdown
    paper = render_report(
        {RunSpec(1, "cfc", False, "exact"): cfc.__class__(**{**vars(cfc), "metadata": {}})},
        {},
        seed=0,
        integrator="euler",
        substeps=1,
        wall_time_s=1.0,
    )
    assert "This robot is not the paper's" not in paper


def test_the_inverse_kinematics_of_the_six_module_arm_is_exact_and_optimal(six):
    """Case 2 placed on the 21-joint arm: the tip follows the path, the exact rates satisfy the
    velocity and acceleration relations, and the fast solver reaches the optimum of the joint-limit
    cost that SciPy's SLSQP (a second algorithm) reaches from the same start."""
    from tests.test_ik_solvers import subsample

    path = case_path(six, 2, 0.01)
    fast = six.inverse_kinematics(path)
    assert fast.success, fast.message
    np.testing.assert_allclose(six.tip_position(fast.q), path.position, rtol=0, atol=1e-9)
    J = six.tip_jacobian(fast.q)
    velocity = np.einsum("nij,nj->ni", J, fast.qd)
    acceleration = np.einsum("nij,nj->ni", J, fast.qdd) + six.bias_accelerations(fast.q, fast.qd).tip
    assert np.abs(velocity - path.velocity).max() <= 1e-8 * np.abs(path.velocity).max()
    assert np.abs(acceleration - path.acceleration).max() <= 1e-8 * np.abs(path.acceleration).max()
    lower, upper = six.parameters.lower, six.parameters.upper
    assert ((fast.q >= lower - 1e-12) & (fast.q <= upper + 1e-12)).all()
    coarse = subsample(path, 9)
    quick = six.inverse_kinematics(coarse)
    reference = six.inverse_kinematics(coarse, solver="slsqp")
    both = quick.samples.success & reference.samples.success
    assert both.sum() >= 8, reference.message
    np.testing.assert_allclose(quick.samples.phi[both], reference.samples.phi[both], rtol=0, atol=1e-12)
    np.testing.assert_allclose(quick.q[both], reference.q[both], rtol=0, atol=1e-5)
