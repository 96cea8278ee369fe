"""One name for the joint limits: ``lower`` and ``upper`` (arrays, m and rad) on the parameters, a
stack, the robot and the results; a robot file's ``[limits]`` pairs are ``RobotParameters.limits``;
``q_min`` and ``q_max`` still answer, with a DeprecationWarning."""

from __future__ import annotations

import dataclasses
import tomllib
import warnings
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

import vgtarm
from vgtarm.model.parameters import JOINT_NAMES
from vgtarm.model.stack import load_stack, stack_from_parameters

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _reference_file() -> dict:
    return tomllib.loads(resources.files("vgtarm.model.data").joinpath("reference_robot.toml").read_text("utf-8"))


def test_the_files_limits_are_the_parameters_limits_lower_and_upper(robot):
    p = robot.parameters
    table = _reference_file()["limits"]
    assert p.limits == tuple(tuple(table[name]) for name in JOINT_NAMES)
    lower, upper = robot.joint_limits()
    for values, column in ((p.lower, 0), (p.upper, 1), (lower, 0), (upper, 1)):
        assert values.dtype == np.float64 and values.shape == (7,)
        np.testing.assert_array_equal(values, [table[name][column] for name in JOINT_NAMES])


@pytest.mark.parametrize("old", ["q_min", "q_max"])
def test_the_old_names_still_answer_with_a_deprecation_warning(robot, old):
    new = {"q_min": "lower", "q_max": "upper"}[old]
    stack = load_stack(EXAMPLES / "six_modules.toml")
    for holder in (robot.parameters, stack):
        with pytest.warns(DeprecationWarning, match=rf"^{old} is deprecated: .* use \.{new}$"):
            value = getattr(holder, old)
        assert isinstance(value, tuple) and all(isinstance(x, float) for x in value)
        assert value == tuple(getattr(holder, new).tolist())


def test_a_paper_robot_as_a_stack_keeps_its_limits_bit_for_bit(robot):
    stack = stack_from_parameters(robot.parameters)
    assert stack.lower.tobytes() == robot.parameters.lower.tobytes()
    assert stack.upper.tobytes() == robot.parameters.upper.tobytes()


def test_a_bad_limits_pair_is_named_by_its_joint(robot):
    p = robot.parameters
    with pytest.raises(vgtarm.ConfigError, match=r"field 'limits\.v1' = \[0\.3, 0\.2\]: expected min < max"):
        dataclasses.replace(p, limits=(p.limits[0], (0.3, 0.2), *p.limits[2:]))
    with pytest.raises(vgtarm.ConfigError, match=r"field 'limits\.p1' = .*: expected 2 numbers"):
        dataclasses.replace(p, limits=(*p.limits[:2], (0.3,), *p.limits[3:]))
    with pytest.raises(vgtarm.ConfigError, match=r"field 'limits' = .*: expected 7 \[min, max\] pairs"):
        dataclasses.replace(p, limits=p.limits[:6])
    data = _reference_file()
    data["limits"]["psi3"] = [1.0, -1.0]
    with pytest.raises(vgtarm.ConfigError, match=r"field 'limits\.psi3' = \[1\.0, -1\.0\]: expected min < max"):
        vgtarm.model.parameters.parameters_from_dict(data)


def test_the_library_itself_uses_no_deprecated_name(robot):
    """A solve, a run, a point, a refused configuration and a stack's conversion, with the
    deprecation turned into an error."""
    from vgtarm.control import ComputedForceControl

    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        ik = robot.inverse_kinematics(vgtarm.paths.case1(dt=1e-3, duration=0.05))
        vgtarm.simulate(robot, ik, ComputedForceControl.with_gains(5000.0, 300.0))
        vgtarm.solve_point(robot, [0.01, 0.0, 0.65])
        with pytest.raises(vgtarm.InputError, match=r"far beyond its limits \[0\.22, 0\.36\]"):
            robot.tip_position(np.full(7, 1e6))
        stack_from_parameters(robot.parameters)
        load_stack(EXAMPLES / "six_modules.toml").lower  # noqa: B018 - the property is the test
