"""The path-wide effort measurement's pieces (benchmarks/bench_path_wide.py, issue 22): its finite
differences are exact on cubics, its inverse dynamics is the compiled model's, its resampling puts
every sample on the path."""

from __future__ import annotations

import numpy as np

from benchmarks.bench_path_wide import difference_matrices, leg_rms, node_functions, to_samples
from vgtarm.experiment.cases import case_path, joint_reference

from .conftest import assert_close, random_configurations


def test_the_differences_are_exact_on_quadratics_and_second_order_on_smooth_signals():
    h, k = 0.01, 12
    t = np.arange(k) * h
    d1, d2 = difference_matrices(k, h)
    q = np.stack([1 + 2 * t - 3 * t**2, 0.5 * t**2])  # (2, k): quadratics, differentiated exactly
    assert_close(q @ d1.T, np.stack([2 - 6 * t, t]), atol=1e-12)
    assert_close(q @ d2.T, np.stack([np.full(k, -6.0), np.full(k, 1.0)]), atol=1e-9)
    errors = []
    for step in (0.02, 0.01):  # halving the step quarters the error of sin's derivatives
        s = np.arange(0, 1 + 1e-12, step)
        a, b = difference_matrices(len(s), step)
        errors.append((np.abs(np.sin(s) @ a.T - np.cos(s)).max(), np.abs(np.sin(s) @ b.T + np.sin(s)).max()))
    assert 3.5 < errors[0][0] / errors[1][0] < 4.5 and 3.5 < errors[0][1] / errors[1][1] < 4.5


def test_the_node_efforts_are_the_models_inverse_dynamics(robot):
    efforts, _, tip = node_functions(robot)
    rng = np.random.default_rng(4)
    q = random_configurations(robot, 5, seed=4)
    qd, qdd, f = rng.normal(size=q.shape), rng.normal(size=q.shape), rng.normal(size=(5, 3)) * 10
    for i in range(5):
        expected = robot.inverse_dynamics(q[i], qd[i], qdd[i], f_tip=f[i])
        assert_close(np.asarray(efforts(q[i], qd[i], qdd[i], f[i], robot.parameter_vector)).ravel(), expected)
        assert_close(np.asarray(tip(q[i], robot.parameter_vector)).ravel(), robot.tip_position(q[i]), atol=1e-14)
    legs = np.array([u == "m" for u in robot.parameters.joint_units])
    assert leg_rms(robot, np.where(legs, 3.0, 100.0)[None, :]) == 3.0  # the twist torque is not a leg force


def test_resampling_puts_every_sample_on_the_path(robot):
    path = case_path(robot, 1)
    reference = joint_reference(robot, 1)
    nodes = np.arange(0, 400, 20)
    t = path.t[: nodes[-1] + 1]
    q = to_samples(robot, path.t[nodes], reference.q[nodes], t, path.position[: len(t)])
    assert np.abs(robot.tip_position(q) - path.position[: len(t)]).max() < 1e-12
    assert_close(q[nodes], reference.q[nodes], atol=1e-12)  # the nodes were on the path: unchanged
    assert np.abs(q - reference.q[: len(t)]).max() < 1e-5  # between them, close to the IK's own answer
