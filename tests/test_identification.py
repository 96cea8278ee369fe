"""Dynamic identification (issue 39): the regressor, the base parameters, the exciting trajectory, the
consistent fit, the refusals, the closed loop with the identified model and ``vgtarm identify``."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest

import vgtarm
from vgtarm.app.cli.identify import add_parser, measurements_csv
from vgtarm.calibration import dynamic, excitation
from vgtarm.errors import InputError
from vgtarm.experiment.cases import joint_reference, run_case
from vgtarm.model.parameters import Body, check_body

#: Noise of the simulated measurements: the issue's 0.5 N on the legs, and 0.5 N m on the twist (the
#: same number: a pessimistic torque sensor for a joint that never needs more than a few N m).
LEG_NOISE, TWIST_NOISE = 0.5, 0.5


def _noise(robot: vgtarm.Robot) -> np.ndarray:
    return np.where(np.array(robot.joint_units) == "rad", TWIST_NOISE, LEG_NOISE)


@pytest.fixture(scope="module")
def paper() -> vgtarm.Robot:
    return vgtarm.load_robot()


@pytest.fixture(scope="module")
def base(paper: vgtarm.Robot) -> dynamic.BaseParameters:
    return dynamic.base_parameters(paper, seed=0)


@pytest.fixture(scope="module")
def trajectory(paper: vgtarm.Robot, base: dynamic.BaseParameters) -> excitation.ExcitingTrajectory:
    return excitation.exciting_trajectory(paper, evaluations=40, base=base, seed=0)


# -- the regressor ---------------------------------------------------------------------------------


@pytest.mark.parametrize("config", [None, "examples/paper_robot.toml", "examples/six_modules.toml"])
def test_regressor_times_standard_parameters_is_the_inverse_dynamics(config: str | None) -> None:
    root = Path(__file__).resolve().parents[1]
    robot = vgtarm.load_robot(None if config is None else root / config)
    q, qd, qdd = dynamic.random_states(robot, 40, seed=3)
    Y = dynamic.regressor(robot, q, qd, qdd)
    forces = robot.inverse_dynamics(q, qd, qdd)
    assert Y.shape == (40, robot.n_joints, len(dynamic.standard_names(robot.parameters)))
    tolerance = 1e-10 * max(1.0, float(np.abs(forces).max()) / 100.0)
    np.testing.assert_allclose(Y @ dynamic.standard_vector(robot.parameters), forces, rtol=0, atol=tolerance)
    # the viscous columns, analytically: qd_i on joint i
    viscous = Y[..., -robot.n_joints :]
    np.testing.assert_allclose(viscous, qd[:, :, None] * np.eye(robot.n_joints), rtol=0, atol=1e-9)


def test_standard_parameters_of_a_point_mass_and_back() -> None:
    c = np.array([0.1, -0.2, 0.3])
    body = Body("b", 2.0, tuple(c), ((1e-3, 0, 0), (0, 1e-3, 0), (0, 0, 1e-3)))  # type: ignore[arg-type]
    values = dynamic.body_standard(body)
    inertia = 1e-3 * np.eye(3) + 2.0 * (c @ c * np.eye(3) - np.outer(c, c))  # parallel axes, by hand
    np.testing.assert_allclose(values[:4], [2.0, *(2.0 * c)])
    np.testing.assert_allclose(
        values[4:], [inertia[0, 0], inertia[1, 1], inertia[2, 2], *inertia[[0, 0, 1], [1, 2, 2]]]
    )
    back = dynamic.body_from_standard(values, "b")
    np.testing.assert_allclose(back.com, c, atol=1e-15)
    np.testing.assert_allclose(back.inertia_matrix, body.inertia_matrix, atol=1e-15)


def test_log_cholesky_is_consistent_and_its_jacobian_matches_differences() -> None:
    rng = np.random.default_rng(1)
    reference = dynamic.body_standard(vgtarm.load_robot().parameters.bodies[2])
    for _ in range(5):
        x = rng.normal(scale=0.5, size=10)
        values, jacobian = dynamic.body_from_log_cholesky(x, reference)
        assert dynamic.is_consistent(values)
        check_body("<test>", "body", dynamic.body_from_standard(values, "b"))  # mass, PD, triangle
        step = 6e-6
        columns = [
            (
                dynamic.body_from_log_cholesky(x + step * e, reference)[0]
                - dynamic.body_from_log_cholesky(x - step * e, reference)[0]
            )
            / (2 * step)
            for e in np.eye(10)
        ]
        np.testing.assert_allclose(jacobian, np.array(columns).T, rtol=1e-6, atol=1e-9 * np.abs(jacobian).max())
        np.testing.assert_allclose(dynamic.log_cholesky_of(values, reference), x, atol=1e-9)


# -- base parameters -------------------------------------------------------------------------------


def test_base_parameters_reproduce_the_forces_and_match_the_svd_rank(
    paper: vgtarm.Robot, base: dynamic.BaseParameters
) -> None:
    q, qd, qdd = dynamic.random_states(paper, 60, seed=7)  # other states than the base was found on
    Y = dynamic.regressor(paper, q, qd, qdd)
    pi = dynamic.standard_vector(paper.parameters)
    np.testing.assert_allclose(base.regressor(Y) @ base.of(pi), Y @ pi, rtol=0, atol=1e-9)
    stacked = Y.reshape(-1, Y.shape[-1])
    singular = np.linalg.svd(stacked / np.maximum(np.linalg.norm(stacked, axis=0), 1e-300), compute_uv=False)
    assert base.size == int(np.sum(singular > 1e-8 * singular[0])) == 27
    assert "platform1.mx" in base.undetermined
    assert np.abs(stacked[:, [base.names.index(name) for name in base.undetermined]]).max() < 1e-9
    assert "end_effector.m + platform2.m" in base.labels


# -- exciting trajectory ---------------------------------------------------------------------------


def test_exciting_trajectory_stays_inside_the_limits(
    paper: vgtarm.Robot, trajectory: excitation.ExcitingTrajectory
) -> None:
    lower, upper = paper.joint_limits()
    assert (trajectory.q >= lower).all() and (trajectory.q <= upper).all()
    assert paper.is_assemblable(trajectory.q, 1e-4).all()
    span = upper - lower
    assert (np.abs(trajectory.qd) <= excitation.SPEED_SPANS * span * (1 + 1e-9)).all()
    assert (np.abs(trajectory.qdd) <= excitation.ACCELERATION_SPANS * span * (1 + 1e-9)).all()
    dt = trajectory.t[1] - trajectory.t[0]  # the analytic rates against differences of the positions
    for rate, derivative in ((trajectory.q, trajectory.qd), (trajectory.qd, trajectory.qdd)):
        size = np.abs(derivative).max(axis=0)
        assert (np.abs(np.gradient(rate, dt, axis=0) - derivative)[1:-1] < 1e-4 * size).all()
    assert trajectory.condition_number < 1e3
    again = excitation.exciting_trajectory(paper, evaluations=40, base=dynamic.base_parameters(paper, seed=0), seed=0)
    np.testing.assert_array_equal(again.q, trajectory.q)  # seeded: the same bit for bit


# -- identification --------------------------------------------------------------------------------


def test_noise_free_data_give_the_base_parameters_exactly(
    paper: vgtarm.Robot, base: dynamic.BaseParameters, trajectory: excitation.ExcitingTrajectory
) -> None:
    truth = dynamic.perturbed_parameters(paper.parameters, seed=4)
    forces = dynamic.simulated_forces(
        paper.with_parameters(truth), trajectory.q, trajectory.qd, trajectory.qdd, noise=0.0
    )
    result = dynamic.identify(paper, trajectory.q, trajectory.qd, trajectory.qdd, forces, base=base)
    expected = base.of(dynamic.standard_vector(truth))
    scale = np.abs(expected).max()
    np.testing.assert_allclose(result.least_squares, expected, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(result.consistent, expected, rtol=0, atol=1e-5 * scale)
    for k in range(len(truth.bodies)):
        assert dynamic.is_consistent(result.standard[10 * k : 10 * k + 10])
    assert min(result.parameters.viscous) >= 0.0


def test_noisy_data_give_estimates_within_their_standard_errors(
    paper: vgtarm.Robot, base: dynamic.BaseParameters, trajectory: excitation.ExcitingTrajectory
) -> None:
    truth = dynamic.perturbed_parameters(paper.parameters, seed=5)
    true = paper.with_parameters(truth)
    forces = dynamic.simulated_forces(true, trajectory.q, trajectory.qd, trajectory.qdd, noise=_noise(paper), seed=5)
    result = dynamic.identify(paper, trajectory.q, trajectory.qd, trajectory.qdd, forces, base=base)
    z = (result.least_squares - base.of(dynamic.standard_vector(truth))) / result.standard_errors
    assert np.abs(z).max() < 4.0
    np.testing.assert_allclose(result.noise, _noise(paper), rtol=0.1)
    assert result.rms_consistent <= 1.01 * result.rms_least_squares


def test_bad_measurements_are_refused_naming_the_row(paper: vgtarm.Robot, base: dynamic.BaseParameters) -> None:
    q, qd, qdd = dynamic.random_states(paper, 30, seed=2)
    forces = paper.inverse_dynamics(q, qd, qdd)
    bad = qd.copy()
    bad[4, 2] = np.nan
    with pytest.raises(InputError, match=r"^row 5: qd\[p1\] = nan: expected a finite number$"):
        dynamic.identify(paper, q, bad, qdd, forces, base=base)
    outside = q.copy()
    outside[11, 0] = 0.5
    with pytest.raises(InputError, match=r"^row 12: q\[s1\] = 0.5: expected a value inside the joint limits"):
        dynamic.identify(paper, outside, qd, qdd, forces, base=base)
    with pytest.raises(InputError, match=r"^samples = 3: expected more than 3 rows"):
        dynamic.identify(paper, q[:3], qd[:3], qdd[:3], forces[:3], base=base)
    still = np.zeros_like(qd)  # at rest: inertias and friction are not excited
    with pytest.raises(InputError, match=r"^data = .*: expected data that (move|excite)"):
        dynamic.identify(paper, q, still, still, paper.inverse_dynamics(q, still, still), base=base)
    flat = q.copy()
    flat[7, :3] = [0.36, 0.22, 0.30]  # module 1's legs: no triangle
    if not paper.is_assemblable(flat[7]):
        with pytest.raises(InputError, match=r"^row 8: q = .*: expected legs that can be assembled"):
            dynamic.identify(paper, flat, qd, qdd, forces, base=base)


# -- the target: case 2 with the identified model ---------------------------------------------------


@pytest.mark.parametrize("seed", [1, 2])
def test_identified_model_tracks_case_2_within_ten_percent_of_the_exact_model(
    paper: vgtarm.Robot, base: dynamic.BaseParameters, trajectory: excitation.ExcitingTrajectory, seed: int
) -> None:
    """Case 2 with the tool force, 1 um encoders, CFC without observer, on the perturbed robot. On
    seed 1 the nominal model misses the target (11 % over): the test tells the models apart."""
    truth = dynamic.perturbed_parameters(paper.parameters, seed=seed)
    true = paper.with_parameters(truth)
    forces = dynamic.simulated_forces(true, trajectory.q, trajectory.qd, trajectory.qdd, noise=_noise(paper), seed=seed)
    identified = dynamic.identify(paper, trajectory.q, trajectory.qd, trajectory.qdd, forces, base=base).parameters
    reference = joint_reference(true, 2)
    errors = {
        label: run_case(
            true,
            2,
            external_force=True,
            reference=reference,
            encoder_resolution=1e-6,
            controller_model=model,
            seed=seed,
        ).summary()["max_tip_error_m"]
        for label, model in (("exact", truth), ("identified", identified), ("nominal", paper.parameters))
    }
    assert errors["identified"] <= 1.1 * errors["exact"]
    if seed == 1:
        assert errors["nominal"] > 1.1 * errors["exact"]


# -- the command -------------------------------------------------------------------------------------


def _run(argv: list[str]) -> int:
    parser = argparse.ArgumentParser()
    add_parser(parser.add_subparsers())
    args = parser.parse_args(["identify", *argv])
    return int(args.run(args))


def test_command_writes_an_excitation_then_identifies_from_its_measurements(
    tmp_path: Path, paper: vgtarm.Robot
) -> None:
    assert _run(["--excite", "--evaluations", "5", "--out", str(tmp_path / "excite")]) == 0
    table = np.loadtxt(tmp_path / "excite" / "excitation.csv", delimiter=",", skiprows=1)
    n = paper.n_joints
    t, q, qd, qdd = table[:, 0], table[:, 1 : 1 + n], table[:, 1 + n : 1 + 2 * n], table[:, 1 + 2 * n :]
    truth = dynamic.perturbed_parameters(paper.parameters, seed=1)
    forces = dynamic.simulated_forces(paper.with_parameters(truth), q, qd, qdd, noise=_noise(paper), seed=1)
    data = tmp_path / "data.csv"
    data.write_text(measurements_csv(paper.joint_names, t, q, qd, qdd, forces))
    assert _run(["--data", str(data), "--out", str(tmp_path / "out")]) == 0
    identified = vgtarm.load_robot(tmp_path / "out" / "identified_robot.toml")
    assert identified.n_joints == n
    np.testing.assert_allclose(identified.parameters.total_mass, truth.total_mass, rtol=0.02)
    lines = (tmp_path / "out" / "base_parameters.csv").read_text().splitlines()
    assert lines[0].startswith("base_parameter,least_squares,standard_error")
    assert any(line.startswith("platform1.mx,undetermined") for line in lines)
    assert (tmp_path / "out" / "residuals.png").stat().st_size > 0
    # positions only: the rates and accelerations from the Savitzky-Golay filter
    names = paper.joint_names
    text = "t," + ",".join(names) + "," + ",".join(f"{x}_F" for x in names) + "\n"
    text += "\n".join(",".join(repr(float(v)) for v in row) for row in np.column_stack([t, q, forces])) + "\n"
    (tmp_path / "positions.csv").write_text(text)
    assert _run(["--data", str(tmp_path / "positions.csv"), "--out", str(tmp_path / "out2")]) == 0


def test_command_refuses_a_bad_cell_in_one_line(tmp_path: Path, paper: vgtarm.Robot) -> None:
    names = paper.joint_names
    header = "t," + ",".join(names) + "," + ",".join(f"{x}_F" for x in names)
    home = ",".join(repr(float(x)) for x in paper.parameters.home)
    data = tmp_path / "bad.csv"
    data.write_text(f"{header}\n0.0,{home},{','.join(['0'] * 7)}\n0.1,{home},{','.join(['x'] * 7)}\n")
    with pytest.raises(InputError, match=r"line 3, column 's1_F': 'x' is not a number"):
        _run(["--data", str(data), "--out", str(tmp_path / "out")])
    assert not (tmp_path / "out").exists()
