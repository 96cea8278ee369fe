"""Jacobians and velocity-product accelerations against finite differences of the kinematics."""

from __future__ import annotations

import numpy as np

from .conftest import assert_close, central_difference, random_configurations


def vee(skew):
    return 0.5 * np.stack(
        [skew[..., 2, 1] - skew[..., 1, 2], skew[..., 0, 2] - skew[..., 2, 0], skew[..., 1, 0] - skew[..., 0, 1]],
        axis=-1,
    )


def body_poses(robot, q):
    """Centres of mass and orientations of the three bodies, rebuilt in NumPy from the frames."""
    fk = robot.forward_kinematics(q)
    origins = [fk.platform_position[..., 0, :], fk.platform_position[..., 1, :], fk.platform_position[..., 1, :]]
    rotations = [fk.platform_rotation[..., 0, :, :], fk.platform_rotation[..., 1, :, :], fk.rotation]
    coms = [o + R @ np.array(b.com) for o, R, b in zip(origins, rotations, robot.parameters.bodies, strict=True)]
    return np.stack(coms, axis=-2), np.stack(rotations, axis=-3)


def angular_jacobian_fd(rotation_of, q, h=1e-6):
    """Angular Jacobian from central differences of a rotation: column i = vee(dR/dq_i R^T)."""
    R = rotation_of(q)
    columns = []
    for i in range(7):
        e = np.zeros(7)
        e[i] = h
        dR = (rotation_of(q + e) - rotation_of(q - e)) / (2 * h)
        columns.append(vee(dR @ np.swapaxes(R, -1, -2)))
    return np.stack(columns, axis=-1)


def test_tip_jacobian_matches_finite_differences(robot):
    q = random_configurations(robot, 200, seed=10)
    assert_close(robot.tip_jacobian(q), central_difference(robot.tip_position, q), rtol=1e-6, atol=1e-8)


def test_angular_jacobian_matches_finite_differences(robot):
    q = random_configurations(robot, 200, seed=11)
    fd = angular_jacobian_fd(lambda x: robot.forward_kinematics(x).rotation, q)
    assert_close(robot.angular_jacobian(q), fd, rtol=1e-6, atol=1e-8)


def test_body_jacobians_match_finite_differences(robot):
    q = random_configurations(robot, 100, seed=12, margin=0.02)
    J_v, J_w = robot.com_jacobians(q)
    fd_v = central_difference(lambda x: body_poses(robot, x)[0], q)
    assert_close(J_v, fd_v, rtol=1e-6, atol=1e-8)
    for k in range(3):
        fd_w = angular_jacobian_fd(lambda x, k=k: body_poses(robot, x)[1][:, k], q)
        assert_close(J_w[:, k], fd_w, rtol=1e-6, atol=1e-8)


def test_bias_accelerations_match_finite_differences(robot):
    """``Jdot qd`` = d/dt (J(q(t)) qd) along ``q(t) = q + t qd``, by central differences in t."""
    rng = np.random.default_rng(13)
    q = random_configurations(robot, 100, seed=13, margin=0.02)
    qd = rng.normal(scale=0.05, size=q.shape)
    h = 1e-6
    bias = robot.bias_accelerations(q, qd)

    def rates(x):
        J_v, J_w = robot.com_jacobians(x)
        return (
            robot.tip_jacobian(x) @ qd[..., None],
            robot.angular_jacobian(x) @ qd[..., None],
            J_v @ qd[:, None, :, None],
            J_w @ qd[:, None, :, None],
        )

    plus, minus = rates(q + h * qd), rates(q - h * qd)
    expected = [(a - b)[..., 0] / (2 * h) for a, b in zip(plus, minus, strict=True)]
    for actual, fd in zip([bias.tip, bias.angular, bias.com, bias.body_angular], expected, strict=True):
        assert_close(actual, fd, rtol=1e-5, atol=1e-8)


def test_tip_velocity_is_jacobian_times_rates(robot):
    rng = np.random.default_rng(14)
    q = random_configurations(robot, 50, seed=14)
    qd = rng.normal(size=q.shape)
    v, w = robot.tip_velocity(q, qd)
    assert_close(v, (robot.tip_jacobian(q) @ qd[..., None])[..., 0], rtol=1e-12, atol=1e-14)
    assert_close(w, (robot.angular_jacobian(q) @ qd[..., None])[..., 0], rtol=1e-12, atol=1e-14)
