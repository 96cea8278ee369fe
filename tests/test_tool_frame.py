"""The tool frame (issue 36, item 1): a stack's ``[end_effector] tool_axis`` and ``tool_edge``.

- the file: a round trip of a turned tool through the TOML writer; the defaults written as before
  (no new key, the writer's text read back to the same text); every refusal in one line naming the
  field, the value and what was expected (a vector that is not unit: its normalised value, which
  pasted back loads);
- the Robot: ``tool_frame`` is a rotation with det 1 whose ``z`` is ``tool_axis``; the default
  tool frame is ``C03`` itself, bit for bit; ``tool_axis(q)`` against an independent route: its
  time derivative by central differences along a joint velocity ``qd`` equals ``w x axis`` with
  ``w = J_W qd`` (the angular Jacobian);
- geometry only: a turned tool changes neither the parameter vector nor the tip nor ``M``;
- the drawing: the segment ``tool_axis`` runs from the tip along ``tool_axis(q)``.

The MJCF site ``tip`` turned to the tool frame is tested in ``tests/test_mujoco_stack.py``.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import vgtarm
from vgtarm.app.pictures.geometry import TOOL_AXIS_FRACTION, mechanism_geometry
from vgtarm.errors import AssemblyError, ConfigError, InputError
from vgtarm.model.robot import is_stack_format
from vgtarm.model.stack import load_stack, stack_from_dict, stack_to_toml

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
#: Central differences of ``tool_axis`` against ``w x axis``: step about ``eps**(1/3)`` (relative).
FD_STEP = 6e-6
FD_TOLERANCE = 1e-7


def _turned_frame(seed: int) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """A random unit axis and a unit edge perpendicular to it (to round-off)."""
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    edge = np.cross(axis, rng.normal(size=3))
    edge /= np.linalg.norm(edge)
    return tuple(float(x) for x in axis), tuple(float(x) for x in edge)  # type: ignore[return-value]


def _turned(robot: vgtarm.Robot, seed: int = 0) -> vgtarm.Robot:
    axis, edge = _turned_frame(seed)
    return robot.with_parameters(replace(robot.parameters, tool_axis=axis, tool_edge=edge))


def _states(robot: vgtarm.Robot, n: int, seed: int) -> np.ndarray:
    """``n`` assemblable configurations within a tenth of each joint's range around home."""
    rng = np.random.default_rng(seed)
    p = robot.parameters
    q = p.home + 0.1 * (p.upper - p.lower) * rng.uniform(-1.0, 1.0, size=(4 * n, robot.n_joints))
    q = q[robot.is_assemblable(q, 1e-3)]
    assert len(q) >= n
    return q[:n]


@pytest.fixture(scope="module")
def planar() -> vgtarm.Robot:
    return vgtarm.load_robot(EXAMPLES / "planar_module.toml")


@pytest.fixture(scope="module", params=["planar_module", "paper_robot", "planar_module recursive"])
def robot(request) -> vgtarm.Robot:
    name, *model = request.param.split()
    return vgtarm.load_robot(EXAMPLES / f"{name}.toml", model=model[0] if model else None)


def _effector(**fields: object) -> dict:
    """The planar module's file as a dict, with ``fields`` set under ``[end_effector]``."""
    data = tomllib.loads((EXAMPLES / "planar_module.toml").read_text())
    data["end_effector"].update(fields)
    return data


# -- the file ------------------------------------------------------------------------------------


def test_a_turned_tool_survives_the_toml_round_trip(planar):
    axis, edge = _turned_frame(1)
    stack = replace(planar.parameters, tool_axis=axis, tool_edge=edge)
    text = stack_to_toml(stack)
    assert f"tool_axis = [{', '.join(repr(x) for x in axis)}]" in text
    assert f"tool_edge = [{', '.join(repr(x) for x in edge)}]" in text
    again = stack_from_dict(tomllib.loads(text))
    assert again == stack and again.tool_axis == axis and again.tool_edge == edge
    np.testing.assert_array_equal(again.tool_rotation, stack.tool_rotation)
    assert stack_to_toml(again) == text
    # only the one that differs from its default is written
    axis_only = stack_to_toml(replace(planar.parameters, tool_axis=(0.0, -1.0, 0.0)))
    assert "tool_axis = [0.0, -1.0, 0.0]" in axis_only and "tool_edge" not in axis_only


#: The shipped stack files (the example robot with actuators is a 7-joint robot file, not a stack).
STACK_EXAMPLES = [path for path in sorted(EXAMPLES.glob("*.toml")) if is_stack_format(tomllib.loads(path.read_text()))]


@pytest.mark.parametrize("path", STACK_EXAMPLES, ids=lambda p: p.stem)
def test_default_tools_are_written_as_before(path):
    """Every shipped stack: no tool_axis or tool_edge written, the identity tool frame, and the
    writer's text read back and written again is the same text, byte for byte."""
    stack = load_stack(path)
    assert stack.tool_axis == (0.0, 0.0, 1.0) and stack.tool_edge == (1.0, 0.0, 0.0)
    np.testing.assert_array_equal(stack.tool_rotation, np.eye(3))
    text = stack_to_toml(stack, header="round trip")
    assert "tool_axis" not in text and "tool_edge" not in text
    again = stack_from_dict(tomllib.loads(text))
    assert again == stack and stack_to_toml(again, header="round trip") == text
    # the old [end_effector] block: its tool line, then the environment
    assert re.search(r"\ntool = \[[^\n]*\]\n\n\[environment\]\n", text)


def test_the_defaults_written_out_load_the_same_stack(planar):
    data = _effector(tool_axis=[0.0, 0.0, 1.0], tool_edge=[1.0, 0.0, 0.0])
    assert stack_from_dict(data) == planar.parameters


def test_a_vector_that_is_not_unit_is_refused_with_its_normalised_value_which_loads(planar):
    with pytest.raises(ConfigError) as refused:
        stack_from_dict(_effector(tool_axis=[0, 1, 1]), source="arm.toml")
    message = str(refused.value)
    assert "\n" not in message
    assert message.startswith("arm.toml: field 'end_effector.tool_axis' = [0.0, 1.0, 1.0]: expected a unit vector")
    assert "(norm 1 within 1e-9), its norm is 1.41421; normalised: [0, 0.707106781187, 0.707106781187]" in message
    pasted = tomllib.loads("v = " + message.split("normalised: ")[1])["v"]
    stack = stack_from_dict(_effector(tool_axis=pasted))
    assert abs(math.hypot(*stack.tool_axis) - 1.0) <= 1e-9
    # the same for the edge (turned about an axis it stays perpendicular to), and a norm near 1
    with pytest.raises(
        ConfigError, match=r"tool_edge' = \[3.0, 4.0, 0.0\]: .* its norm is 5; normalised: \[0.6, 0.8, 0\]"
    ):
        stack_from_dict(_effector(tool_edge=[3, 4, 0]))
    with pytest.raises(ConfigError, match=r"its norm is 1.00000001; normalised: \[0, 0, 1\]"):
        stack_from_dict(_effector(tool_axis=[0, 0, 1.00000001]))
    assert stack_from_dict(_effector(tool_axis=[0, 0, 1 + 1e-10])).tool_axis == (0.0, 0.0, 1 + 1e-10)


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        (
            {"tool_axis": [0, 0, 0]},
            r"'end_effector.tool_axis' = \[0.0, 0.0, 0.0\]: expected a unit vector .*not the zero",
        ),
        ({"tool_edge": [0.0, 0.0, 0.0]}, r"'end_effector.tool_edge' = \[0.0, 0.0, 0.0\]: expected a unit vector"),
        ({"tool_axis": [0, 0, math.nan]}, r"'end_effector.tool_axis' = \[0.0, 0.0, nan\]: expected 3 finite numbers"),
        ({"tool_edge": [math.inf, 0, 0]}, r"'end_effector.tool_edge' = \[inf, 0.0, 0.0\]: expected 3 finite numbers"),
        ({"tool_axis": [0, 1]}, r"'end_effector.tool_axis' = \[0, 1\]: expected \[x, y, z\] \(a list of 3"),
        ({"tool_edge": "x"}, r"'end_effector.tool_edge' = 'x': expected \[x, y, z\]"),
        (
            {"tool_edge": [0, 0.6, 0.8]},
            r"'end_effector.tool_edge' = \[0.0, 0.6, 0.8\]: expected a direction perpendicular to tool_axis = "
            r"\[0, 0, 1\] \(\|axis . edge\| <= 1e-9\), axis . edge is 0.8; its part across the axis, "
            r"normalised: \[0, 1, 0\]",
        ),
        ({"tool_axis": [1, 0, 0]}, r"'end_effector.tool_edge' = \[1.0, 0.0, 0.0\]: expected a direction perp"),
    ],
)
def test_bad_tool_frames_are_refused_in_one_line(fields, message):
    with pytest.raises(ConfigError, match=message) as refused:
        stack_from_dict(_effector(**fields), source="arm.toml")
    assert "\n" not in str(refused.value) and str(refused.value).startswith("arm.toml: field 'end_effector.tool_")


def test_a_stack_built_directly_is_checked_too(planar):
    with pytest.raises(
        ConfigError, match=r"field 'end_effector.tool_edge' = \[0.0, 1e-08, 1.0\]: expected a direction"
    ):
        replace(planar.parameters, tool_edge=(0, 1e-8, 1))
    # perpendicular within 1e-9 is accepted, and the frame is made a rotation to round-off
    edge = (math.sqrt(1 - 1e-20), 0.0, 1e-10)
    rotation = replace(planar.parameters, tool_edge=edge).tool_rotation
    np.testing.assert_allclose(rotation.T @ rotation, np.eye(3), rtol=0, atol=1e-15)


# -- the Robot -----------------------------------------------------------------------------------


def test_the_default_tool_frame_is_c03_itself(robot):
    reference = vgtarm.load_robot()
    for r in (robot, reference):
        q = _states(r, 6, seed=2)
        fk = r.forward_kinematics(q)
        tip, rotation = r.tool_frame(q)
        np.testing.assert_array_equal(r.tool_rotation, np.eye(3))
        np.testing.assert_array_equal(tip, fk.tip)
        np.testing.assert_array_equal(rotation, fk.rotation)
        np.testing.assert_array_equal(r.tool_axis(q), fk.rotation[..., :, 2])


def test_the_tool_frame_is_a_rotation_whose_z_is_the_tool_axis(robot):
    turned = _turned(robot, seed=3)
    axis, edge = np.array(turned.parameters.tool_axis), np.array(turned.parameters.tool_edge)
    B = turned.tool_rotation
    np.testing.assert_allclose(B[:, 2], axis, rtol=0, atol=1e-15)
    np.testing.assert_allclose(B[:, 0], edge, rtol=0, atol=1e-15)
    np.testing.assert_allclose(B[:, 1], np.cross(axis, edge), rtol=0, atol=1e-15)
    q = _states(robot, 8, seed=4).reshape(2, 4, robot.n_joints)  # batched like forward_kinematics
    tip, rotation = turned.tool_frame(q)
    assert tip.shape == (2, 4, 3) and rotation.shape == (2, 4, 3, 3)
    fk = turned.forward_kinematics(q)
    np.testing.assert_array_equal(tip, fk.tip)
    np.testing.assert_allclose(rotation, fk.rotation @ B, rtol=0, atol=1e-15)
    eye = np.broadcast_to(np.eye(3), rotation.shape)
    np.testing.assert_allclose(np.swapaxes(rotation, -1, -2) @ rotation, eye, rtol=0, atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(rotation), 1.0, rtol=0, atol=1e-14)
    tool_axis = turned.tool_axis(q)
    assert tool_axis.shape == (2, 4, 3)
    np.testing.assert_allclose(rotation[..., :, 2], tool_axis, rtol=0, atol=1e-15)
    # a single configuration, and the property is a copy
    single_tip, single = turned.tool_frame(q[0, 0])
    assert single_tip.shape == (3,) and single.shape == (3, 3)
    turned.tool_rotation[:] = 0.0
    np.testing.assert_array_equal(turned.tool_rotation, B)


def test_the_tool_axis_turns_with_the_end_effectors_angular_velocity(robot):
    """d/dt (C03 axis) along ``q + t qd`` by central differences equals ``(J_W qd) x (C03 axis)``."""
    turned = _turned(robot, seed=5)
    rng = np.random.default_rng(6)
    span = turned.parameters.upper - turned.parameters.lower
    for q in _states(turned, 5, seed=7):
        qd = span * rng.uniform(-1.0, 1.0, size=turned.n_joints)
        h = FD_STEP
        rate = (turned.tool_axis(q + h * qd) - turned.tool_axis(q - h * qd)) / (2 * h)
        omega = turned.angular_jacobian(q) @ qd
        expected = np.cross(omega, turned.tool_axis(q))
        assert np.linalg.norm(rate - expected) <= FD_TOLERANCE * np.linalg.norm(expected)


def test_the_tool_frame_is_geometry_only(planar):
    turned = _turned(planar, seed=8)
    np.testing.assert_array_equal(turned.parameter_vector, planar.parameter_vector)
    assert turned.fingerprint == planar.fingerprint
    q = _states(planar, 4, seed=9)
    np.testing.assert_array_equal(turned.tool_frame(q)[0], planar.tip_position(q))
    np.testing.assert_array_equal(turned.mass_matrix(q), planar.mass_matrix(q))


def _refusal(action) -> str:
    with pytest.raises((InputError, AssemblyError)) as refused:
        action()
    return f"{type(refused.value).__name__}: {refused.value}"


def test_the_tool_frame_checks_q_as_the_forward_kinematics_does(planar):
    """The same refusal, word for word, as :meth:`forward_kinematics` for each bad ``q``."""
    turned = _turned(planar, seed=12)
    n, home = planar.n_joints, planar.parameters.home
    unassemblable = home.copy()
    unassemblable[2] = 10.0 * planar.parameters.upper[2]  # p far too long for s and v
    bad = [
        np.zeros(n + 1),
        np.full(n, np.nan),
        home.astype(complex),
        [str(x) for x in home],
        home - 1e3,
        unassemblable,
        np.stack([home, np.full(n, np.inf)]),
    ]
    for q in bad:
        expected = _refusal(lambda q=q: planar.forward_kinematics(q))
        for robot in (planar, turned):
            assert _refusal(lambda q=q, robot=robot: robot.tool_frame(q)) == expected
            assert _refusal(lambda q=q, robot=robot: robot.tool_axis(q)) == expected


# -- the drawing ---------------------------------------------------------------------------------


def test_the_drawing_shows_the_tool_axis_from_the_tip(planar):
    turned = _turned(planar, seed=10)
    q = _states(turned, 1, seed=11)[0]
    geometry = mechanism_geometry(turned, q)
    segment = geometry.segment("tool_axis")
    assert segment.kind == "tool_axis" and segment.joint is None
    np.testing.assert_allclose(segment.start, turned.tip_position(q), rtol=0, atol=1e-15)
    length = TOOL_AXIS_FRACTION * turned.parameters.modules[0].b
    np.testing.assert_allclose(segment.end - segment.start, length * turned.tool_axis(q), rtol=0, atol=1e-15)


def test_describe_prints_the_tool_frame(planar, tmp_path, capsys):
    from vgtarm.app.cli.command import main

    axis, edge = _turned_frame(1)
    path = tmp_path / "turned.toml"
    path.write_text(stack_to_toml(replace(planar.parameters, tool_axis=axis, tool_edge=edge)))
    assert main(["describe", "--config", str(path)]) == 0
    line = next(row for row in capsys.readouterr().out.splitlines() if row.startswith("tool axis"))
    numbers = [float(v) for v in re.findall(r"-?\d+(?:\.\d+)?(?:e-?\d+)?", line)]
    assert np.allclose(numbers[:3], axis, atol=1e-6) and np.allclose(numbers[3:6], edge, atol=1e-6)
