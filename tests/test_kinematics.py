"""Forward kinematics: reference pose, loop closure, frame composition, assembly errors."""

from __future__ import annotations

import numpy as np
import pytest

import vgtarm
from vgtarm.model.assembly import triangle_margins

from .conftest import assert_close, random_configurations


def rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def test_tip_at_home_is_the_reference_point(robot):
    fk = robot.forward_kinematics(robot.parameters.home)
    assert_close(fk.tip, [0.0, 0.0, 0.66], rtol=0, atol=1e-9)
    assert_close(fk.rotation, np.eye(3), rtol=0, atol=1e-12)
    assert_close(fk.platform_position, [[0, 0, 0.28], [0, 0, 0.56]], rtol=0, atol=1e-12)


def test_loop_closure_equations_hold(robot):
    """Paper eqs. 1-4 for both modules over a thousand random assemblable configurations."""
    q = random_configurations(robot, 1500, seed=1, margin=1e-4)
    passive = robot.forward_kinematics(q).passive
    p = robot.parameters
    for k in range(2):
        s, v, pp = q[:, 3 * k], q[:, 3 * k + 1], q[:, 3 * k + 2]
        alpha, beta, gamma, theta = passive[:, k].T
        b, d = p.b[k], p.d[k]
        assert np.abs(2 * b + v * np.cos(gamma) - pp * np.cos(beta)).max() < 1e-12
        assert np.abs(v * np.sin(gamma) - pp * np.sin(beta)).max() < 1e-12
        assert np.abs(s * np.cos(alpha) + 2 * d * np.cos(theta) - pp * np.cos(beta)).max() < 1e-12
        assert np.abs(s * np.sin(alpha) + 2 * d * np.sin(theta) - pp * np.sin(beta)).max() < 1e-12
        # Assembly mode of the spec: B' above the base.
        assert ((beta > 0) & (beta < np.pi)).all()


def test_frames_compose_as_in_eqs_6_to_11(robot):
    """Tip (eq. 6), centres (eqs. 9-10) and orientation (eq. 11) rebuilt from the passive angles."""
    q = random_configurations(robot, 50, seed=2)
    fk = robot.forward_kinematics(q)
    p = robot.parameters
    for i in range(len(q)):
        a1, _, _, t1 = fk.passive[i, 0]
        a2, _, _, t2 = fk.passive[i, 1]
        r1 = np.array(
            [0, q[i, 0] * np.cos(a1) + p.d[0] * np.cos(t1) - p.b[0], q[i, 0] * np.sin(a1) + p.d[0] * np.sin(t1)]
        )
        r2 = np.array(
            [-q[i, 3] * np.cos(a2) - p.d[1] * np.cos(t2) + p.b[1], 0, q[i, 3] * np.sin(a2) + p.d[1] * np.sin(t2)]
        )
        C01, C02 = rx(t1), rx(t1) @ ry(t2)
        tip = r1 + C01 @ r2 + p.h1 * C02 @ np.array([0, 0, 1])
        assert_close(fk.tip[i], tip, rtol=0, atol=1e-14)
        assert_close(fk.rotation[i], C02 @ rz(q[i, 6]), rtol=0, atol=1e-14)
        assert_close(fk.platform_rotation[i, 1], C02, rtol=0, atol=1e-14)
        assert_close(fk.platform_position[i, 0], r1, rtol=0, atol=1e-14)


def test_rotation_is_proper(robot):
    R = robot.forward_kinematics(random_configurations(robot, 500, seed=3)).rotation
    assert_close(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), rtol=0, atol=1e-13)
    assert_close(np.linalg.det(R), np.ones(len(R)), rtol=0, atol=1e-13)


def test_batch_shapes_broadcast_and_match_single_calls(robot):
    q = random_configurations(robot, 12, seed=4).reshape(3, 4, 7)
    fk = robot.forward_kinematics(q)
    assert fk.tip.shape == (3, 4, 3)
    assert fk.rotation.shape == (3, 4, 3, 3)
    assert fk.passive.shape == (3, 4, 2, 4)
    assert fk.platform_rotation.shape == (3, 4, 2, 3, 3)
    single = robot.forward_kinematics(q[1, 2])
    assert fk.tip.shape[-1:] == single.tip.shape
    np.testing.assert_array_equal(fk.tip[1, 2], single.tip)
    np.testing.assert_array_equal(robot.tip_position(q), fk.tip)


def test_unassemblable_legs_raise_and_never_give_nan(robot):
    rng = np.random.default_rng(5)
    p = robot.parameters
    q = rng.uniform(p.lower, p.upper, size=(4000, 7))
    ok = (triangle_margins(q, p.b, p.d) > 0).all(axis=1)
    assert 0.02 < 1 - ok.mean() < 0.2  # the spec's "about 7 %"
    assert np.isfinite(robot.forward_kinematics(q[ok]).tip).all()
    with pytest.raises(vgtarm.AssemblyError, match=r"module \d cannot be assembled.*triangle inequality"):
        robot.forward_kinematics(q[~ok][0])
    with pytest.raises(vgtarm.AssemblyError, match="configuration"):
        robot.forward_kinematics(q)


@pytest.mark.parametrize(
    ("q", "module", "inequality"),
    [
        ([0.22, 0.28, 0.46, 0.28, 0.28, 0.37, 0], 1, "s + 2d > p"),
        ([0.28, 0.28, 0.37, 0.28, 0.10, 0.45, 0], 2, "2b + v > p"),
    ],
)
def test_assembly_error_names_module_and_inequality(robot, q, module, inequality):
    with pytest.raises(vgtarm.AssemblyError) as info:
        robot.forward_kinematics(q)
    assert f"module {module}" in str(info.value)
    assert inequality in str(info.value)


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ([0.28] * 6, r"shape \(\.\.\., 7\)"),
        ([0.28] * 6 + [np.nan], "finite"),
        ("home", "array of numbers"),
    ],
)
def test_bad_joint_input_is_a_clear_error(robot, value, message):
    with pytest.raises(vgtarm.InputError, match=message):
        robot.forward_kinematics(value)
