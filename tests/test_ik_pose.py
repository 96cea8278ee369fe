"""The full-pose variant: tip point and orientation given, one degree of redundancy left to Phi."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from scipy.spatial.transform import Rotation

from vgtarm import paths
from vgtarm.errors import InputError
from vgtarm.ik import OrientationPath

from .conftest import assert_close


@pytest.fixture(scope="module")
def held(robot):
    path = paths.case2(0.02)
    return path, robot.inverse_kinematics(path, pose="hold")


def phi_gradient(robot, q):
    lo, hi = robot.parameters.lower, robot.parameters.upper
    return 2.0 / 7.0 * (q - (lo + hi) / 2) / (hi - lo) ** 2


def test_position_and_held_orientation_are_met(robot, held):
    path, result = held
    assert result.success, result.message
    assert result.task == "pose"
    target = robot.forward_kinematics(robot.inverse_kinematics(path).q[0]).rotation
    assert_close(result.orientation, np.broadcast_to(target, result.orientation.shape), rtol=0, atol=0)
    fk = robot.forward_kinematics(result.q)
    assert_close(fk.tip, path.position, rtol=0, atol=1e-9, what="tip")
    assert_close(fk.rotation, result.orientation, rtol=0, atol=1e-9, what="orientation")
    assert result.samples.orientation_error.max() <= 1e-9


def test_one_redundant_degree_of_freedom_is_optimised(robot, held):
    _, result = held
    J = np.concatenate([robot.tip_jacobian(result.q), robot.angular_jacobian(result.q)], axis=1)
    g = phi_gradient(robot, result.q)
    for i in range(0, len(result), 10):
        Z = scipy.linalg.null_space(J[i])
        assert Z.shape == (7, 1), "six independent task equations leave one direction"
        assert abs(float(Z[:, 0] @ g[i])) <= 1e-9


def test_pose_agrees_with_ipopt(robot, held):
    path, result = held
    idx = np.arange(0, len(path), 25)
    sub = paths.TipPath("sub", path.t[idx], path.position[idx], path.velocity[idx], path.acceleration[idx])
    ipopt = robot.inverse_kinematics(sub, pose=result.orientation[0], solver="ipopt")
    assert ipopt.success, ipopt.message
    assert_close(ipopt.samples.phi, result.samples.phi[idx], rtol=0, atol=1e-9)


def test_pose_rates_keep_orientation_still_and_follow_the_tip(robot, held):
    path, result = held
    J = robot.tip_jacobian(result.q)
    Jw = robot.angular_jacobian(result.q)
    bias = robot.bias_accelerations(result.q, result.qd)
    assert_close(np.einsum("nij,nj->ni", J, result.qd), path.velocity, rtol=0, atol=1e-10)
    assert_close(np.einsum("nij,nj->ni", Jw, result.qd), 0.0, rtol=0, atol=1e-10)
    assert_close(np.einsum("nij,nj->ni", J, result.qdd) + bias.tip, path.acceleration, rtol=0, atol=1e-9)
    assert_close(np.einsum("nij,nj->ni", Jw, result.qdd) + bias.angular, 0.0, rtol=0, atol=1e-9)


def test_turning_orientation_with_exact_rates(robot):
    """A target turning about the vertical at a known rate: the twist joint follows it exactly."""
    path = paths.case2(0.02, durations=(1.0, 1.0))
    base = robot.forward_kinematics(robot.inverse_kinematics(path).q[0]).rotation
    rate = 0.3  # rad/s about z of F0
    rotation = Rotation.from_rotvec(np.outer(rate * path.t, [0, 0, 1])).as_matrix() @ base
    target = OrientationPath(rotation, angular_velocity=[0, 0, rate], angular_acceleration=[0, 0, 0])
    result = robot.inverse_kinematics(path, pose=target)
    assert result.success, result.message
    assert result.samples.orientation_error.max() <= 1e-9
    Jw = robot.angular_jacobian(result.q)
    bias = robot.bias_accelerations(result.q, result.qd)
    assert_close(np.einsum("nij,nj->ni", Jw, result.qd), np.tile([0, 0, rate], (len(path), 1)), rtol=0, atol=1e-9)
    assert_close(np.einsum("nij,nj->ni", Jw, result.qdd) + bias.angular, 0.0, rtol=0, atol=1e-9)
    with pytest.raises(InputError, match="angular velocity and acceleration"):
        robot.inverse_kinematics(path, pose=rotation)
    robot.inverse_kinematics(path, pose=rotation, rates="finite_difference")


@pytest.mark.parametrize(
    ("pose", "message"),
    [
        (np.eye(3) * 2, "not a rotation matrix"),
        (np.zeros((2, 2)), "shape"),
        ("sideways", "pose must be"),
        (np.diag([1.0, 1.0, -1.0]), "not a rotation matrix"),
    ],
)
def test_bad_pose_is_a_clear_error(robot, pose, message):
    with pytest.raises(InputError, match=message):
        robot.inverse_kinematics(paths.case2(0.1), pose=pose)
