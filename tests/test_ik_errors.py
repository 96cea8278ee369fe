"""Inverse-kinematics errors: unreachable targets, invalid paths, unknown names and options."""

from __future__ import annotations

import numpy as np
import pytest

from vgtarm import paths
from vgtarm.errors import InputError, PathError, UnreachableError, VgtarmError


def test_unreachable_point_names_time_target_and_residual(robot):
    position = np.array([[0.0, 0.0, 0.66], [0.0, 0.0, 0.66], [1.0, 0.0, 0.66], [0.0, 0.0, 0.66]])
    path = paths.TipPath("jump", np.arange(4) * 0.1, position, np.zeros((4, 3)), np.zeros((4, 3)))
    with pytest.raises(UnreachableError) as raised:
        robot.inverse_kinematics(path)
    message = str(raised.value)
    assert "sample 2 at t = 0.2 s" in message
    assert "(1, 0, 0.66) m" in message
    residual = float(message.split(" is ")[-1].split(" m")[0])
    assert 0.5 < residual < 1.0  # about 1 m away, minus the reach of the arm
    assert isinstance(raised.value, RuntimeError) and isinstance(raised.value, VgtarmError)


@pytest.mark.parametrize("solver", ["fast", "reference"])
def test_path_leaving_the_workspace_is_never_returned(robot, solver):
    path = paths.waypoints([0.0, 1.0], [(0.0, 0.0, 0.66), (0.0, 0.0, 0.95)], dt=0.05, blend="cubic")
    with pytest.raises(UnreachableError, match=r"sample \d+ at t = [\d.]+ s cannot be reached"):
        robot.inverse_kinematics(path, solver=solver)


def test_invalid_path_is_a_path_error(robot):
    with pytest.raises(PathError, match="vgtarm.paths.TipPath"):
        robot.inverse_kinematics(np.zeros((10, 3)))  # type: ignore[arg-type]
    with pytest.raises(PathError):
        paths.from_samples([0.0, 1.0, 1.0], [(0, 0, 0.66)] * 3)


def test_unknown_solver_lists_the_valid_ones(robot):
    with pytest.raises(InputError, match="valid solvers are fast, ipopt, reference, slsqp"):
        robot.inverse_kinematics(paths.case2(0.1), solver="fmincon")


def test_unknown_rates_mode_and_option(robot):
    with pytest.raises(InputError, match="valid modes are exact, finite_difference"):
        robot.inverse_kinematics(paths.case2(0.1), rates="euler")
    with pytest.raises(InputError, match="unknown inverse-kinematics option 'tolerance'; valid options are margin"):
        robot.inverse_kinematics(paths.case2(0.1), tolerance=1e-3)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"margin": 0.0}, r"^margin = 0\.0: expected a finite number > 0 \(m\)$"),
        ({"margin": -1e-3}, r"^margin = -0\.001: expected a finite number > 0"),
        ({"max_iterations": 0}, "^max_iterations = 0: expected a whole number >= 1$"),
        ({"initial_guess": [0.3] * 6}, r"^initial_guess\.shape = \(6,\): expected \(7,\)$"),
        ({"initial_guess": [0.3] * 6 + [float("nan")]}, r"^initial_guess\[6\] = nan: expected a finite number$"),
        ({"initial_guess": [0.22, 0.3, 0.46, 0.3, 0.3, 0.3, 0.0]}, "cannot be assembled"),
        ({"fallback": "yes"}, "^fallback = 'yes': expected True or False$"),
    ],
)
def test_bad_option_values(robot, options, message):
    with pytest.raises(InputError, match=message):
        robot.inverse_kinematics(paths.case2(0.1), **options)
