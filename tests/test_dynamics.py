"""Virtual-work dynamics against independent computations and physical identities."""

from __future__ import annotations

import numpy as np
import pytest

from vgtarm.model.compiled import InterpretedBackend, build_functions
from vgtarm.model.robot import Robot

from .conftest import assert_close, central_difference, random_configurations
from .test_jacobians import angular_jacobian_fd, body_poses


def test_mass_matrix_is_symmetric_positive_definite(robot):
    M = robot.mass_matrix(random_configurations(robot, 2000, seed=20, margin=0.0))
    assert_close(M, np.swapaxes(M, -1, -2), rtol=1e-13, atol=1e-14)
    assert (np.linalg.eigvalsh(M)[:, 0] > 0).all()


def test_mass_matrix_is_hessian_of_kinetic_energy_from_body_velocities(robot):
    """``T = sum 1/2 m |v|^2 + 1/2 w.I w`` with body velocities from finite differences of poses."""
    q = random_configurations(robot, 40, seed=21, margin=0.02)
    J_v = central_difference(lambda x: body_poses(robot, x)[0], q)  # (n, 3 bodies, 3, 7)
    rotations = body_poses(robot, q)[1]
    expected = np.zeros((len(q), 7, 7))
    for k, body in enumerate(robot.parameters.bodies):
        J_w = angular_jacobian_fd(lambda x, k=k: body_poses(robot, x)[1][:, k], q)
        R = rotations[:, k]
        inertia = R @ body.inertia_matrix @ np.swapaxes(R, -1, -2)
        expected += body.mass * np.swapaxes(J_v[:, k], -1, -2) @ J_v[:, k]
        expected += np.swapaxes(J_w, -1, -2) @ inertia @ J_w
    assert_close(robot.mass_matrix(q), expected, rtol=1e-6, atol=1e-9)


def test_gravity_term_is_gradient_of_potential_energy(robot):
    q = random_configurations(robot, 50, seed=22, margin=0.02)
    masses = np.array([b.mass for b in robot.parameters.bodies])
    g = np.array(robot.parameters.gravity)

    def potential(x):
        return -(masses[:, None] * body_poses(robot, x)[0]).sum(axis=-2) @ g

    assert_close(robot.bias_forces(q, np.zeros(7)), central_difference(potential, q), rtol=1e-6, atol=1e-7)


def test_velocity_products_follow_lagrange_equations(robot):
    """``C(q, qd) - C(q, 0) - D qd = Mdot qd - 1/2 d/dq (qd^T M qd)``, derivatives of M by FD."""
    rng = np.random.default_rng(23)
    q = random_configurations(robot, 50, seed=23, margin=0.02)
    qd = rng.normal(scale=0.1, size=q.shape)
    h = 1e-6
    M_dot = (robot.mass_matrix(q + h * qd) - robot.mass_matrix(q - h * qd)) / (2 * h)
    dM = central_difference(robot.mass_matrix, q)  # (n, 7, 7, 7): dM[..., k] = dM/dq_k
    quadratic = np.einsum("ni,nijk,nj->nk", qd, dM, qd)
    expected = (M_dot @ qd[..., None])[..., 0] - 0.5 * quadratic
    friction = np.array(robot.parameters.viscous) * qd
    actual = robot.bias_forces(q, qd) - robot.bias_forces(q, np.zeros(7)) - friction
    assert_close(actual, expected, rtol=1e-5, atol=1e-8)


def test_inverse_dynamics_returns_the_applied_efforts(robot):
    rng = np.random.default_rng(24)
    q = random_configurations(robot, 500, seed=24)
    qd = rng.normal(scale=0.2, size=q.shape)
    F = rng.normal(scale=50.0, size=q.shape)
    f_tip = rng.normal(scale=10.0, size=(len(q), 3))
    qdd = robot.forward_dynamics(q, qd, F, f_tip)
    assert_close(robot.inverse_dynamics(q, qd, qdd, f_tip), F, rtol=1e-9, atol=1e-9)
    M, C = robot.mass_matrix(q), robot.bias_forces(q, qd)
    generalized = (np.swapaxes(robot.tip_jacobian(q), -1, -2) @ f_tip[..., None])[..., 0]
    assert_close((M @ qdd[..., None])[..., 0] + C, F + generalized, rtol=1e-9, atol=1e-9)


def test_tip_force_acts_through_the_transposed_tip_jacobian(robot):
    rng = np.random.default_rng(25)
    q = random_configurations(robot, 100, seed=25)
    qd = rng.normal(scale=0.2, size=q.shape)
    F = rng.normal(scale=50.0, size=q.shape)
    f_tip = rng.normal(scale=10.0, size=(len(q), 3))
    generalized = (np.swapaxes(robot.tip_jacobian(q), -1, -2) @ f_tip[..., None])[..., 0]
    assert_close(
        robot.forward_dynamics(q, qd, F, f_tip), robot.forward_dynamics(q, qd, F + generalized), rtol=1e-10, atol=1e-10
    )


def _energy_mismatch(robot, dt: float, duration: float = 0.2) -> float:
    """RK4 free motion under gravity, friction, actuator and tip forces; returns the worst
    ``|E(t) - E(0) - W_actuators(t) - W_tip(t) + W_friction(t)|`` along the run."""
    p = robot.parameters
    D = np.array(p.viscous)
    hold = robot.bias_forces(p.home, np.zeros(7))  # efforts that hold the home pose
    f_tip = np.array([3.0, -2.0, 5.0])

    def force(t):
        return hold + 20.0 * np.sin(7.0 * t + np.arange(7))

    def rhs(t, x):
        q, qd = x[:7], x[7:14]
        qdd = robot.forward_dynamics(q, qd, force(t), f_tip)
        v_tip = robot.tip_jacobian(q) @ qd
        power = force(t) @ qd + f_tip @ v_tip - qd @ (D * qd)
        return np.concatenate([qd, qdd, [power]])

    def total_energy(x):
        kinetic, potential = robot.energy(x[:7], x[7:14])
        return float(kinetic + potential)

    x = np.concatenate([p.home, 0.05 * np.cos(np.arange(7)), [0.0]])
    e0 = total_energy(x)
    worst = 0.0
    t = 0.0
    for _ in range(round(duration / dt)):
        k1 = rhs(t, x)
        k2 = rhs(t + dt / 2, x + dt / 2 * k1)
        k3 = rhs(t + dt / 2, x + dt / 2 * k2)
        k4 = rhs(t + dt, x + dt * k3)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        t += dt
        worst = max(worst, abs(total_energy(x) - e0 - x[14]))
    assert robot.is_assemblable(x[:7])
    return worst


def test_power_balance_holds_to_integrator_accuracy(robot):
    # Friction makes the legs stiff (D/M up to about 480 1/s): RK4 needs dt below about 5 ms.
    coarse = _energy_mismatch(robot, 2e-3)
    fine = _energy_mismatch(robot, 1e-3)
    assert fine < 1e-5  # J, against a total energy of about 30 J
    assert coarse / fine > 8.0  # RK4: the mismatch falls as dt^4 (ratio 16)


@pytest.fixture(scope="module")
def interpreted(robot) -> Robot:
    return Robot(robot.parameters, InterpretedBackend(build_functions()))


def test_compiled_and_interpreted_backends_agree(robot, interpreted):
    rng = np.random.default_rng(26)
    q = random_configurations(robot, 20, seed=26)
    qd = rng.normal(size=q.shape)
    F = rng.normal(size=q.shape)
    assert_close(interpreted.forward_dynamics(q, qd, F), robot.forward_dynamics(q, qd, F), rtol=1e-12, atol=1e-12)
    assert_close(interpreted.forward_kinematics(q).tip, robot.forward_kinematics(q).tip, rtol=0, atol=1e-15)
