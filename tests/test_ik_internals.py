"""Building blocks of the fast solver: interpolation, levels, parallel continuation, verification."""

from __future__ import annotations

import numpy as np

from vgtarm import paths
from vgtarm.ik import fast as sampling
from vgtarm.ik import newton
from vgtarm.ik import newton as continuation
from vgtarm.ik.kkt import ldl_pivots
from vgtarm.ik.options import NewtonSettings
from vgtarm.ik.problem import BatchState, IKProblem
from vgtarm.ik.solve import _task

from .conftest import assert_close


def test_quintic_hermite_is_exact_on_quintics():
    rng = np.random.default_rng(0)
    c = rng.normal(size=(6, 2))
    t_known = np.array([0.0, 0.4, 1.1, 1.5])
    powers = np.arange(6)

    def poly(t, d=0):
        out = np.zeros((t.size, 2))
        for k in powers[d:]:
            factor = np.prod(np.arange(k - d + 1, k + 1)) if d else 1.0
            out += factor * t[:, None] ** (k - d) * c[k]
        return out

    t = np.linspace(0.0, 1.5, 31)
    value = sampling.quintic_hermite(t_known, poly(t_known), poly(t_known, 1), poly(t_known, 2), t)
    assert_close(value, poly(t), rtol=1e-12, atol=1e-12)


def test_levels_nest_and_end_with_every_sample():
    strides = sampling.level_strides(6284)
    assert strides == [512, 64, 8, 1]
    levels = [set(sampling.level_indices(6284, s).tolist()) for s in strides]
    assert all(a <= b for a, b in zip(levels, levels[1:], strict=False))
    assert levels[-1] == set(range(6284)) and 6283 in levels[0]
    points = paths.case1(1e-3).position
    refined = sampling.refine_by_distance(sampling.level_indices(6284, 512), points, 0.02)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    assert np.diff(arc[refined]).max() <= 0.02 + 1e-3


def test_parallel_continuation_equals_the_sequential_loop(robot):
    path = paths.case1(0.25)
    problem = IKProblem.from_parameters(robot.parameters)
    task = _task(robot, path, None)
    n = len(path)
    start = {"q": robot.parameters.home, "lam": np.zeros(3), "mu": np.zeros(16), "active": np.zeros(16, bool)}
    parallel = BatchState.empty(n, 3, 16)
    continuation.solve_in_order(problem, task, parallel, np.arange(n), start, NewtonSettings())
    sequential = BatchState.empty(n, 3, 16)
    for i in range(n):
        source = start if i == 0 else {k: getattr(sequential, k)[i - 1] for k in start}
        for name, value in source.items():
            getattr(sequential, name)[i] = value
        assert newton.iterate(problem, task, sequential, np.array([i]), NewtonSettings())[0]
    assert parallel.converged.all()
    assert_close(parallel.q, sequential.q, rtol=0, atol=1e-10)


def test_ldl_pivots_detect_indefinite_matrices():
    rng = np.random.default_rng(1)
    B = rng.normal(size=(50, 7, 7))
    spd = B @ B.transpose(0, 2, 1) + 0.1 * np.eye(7)
    indefinite = spd - 1.01 * np.linalg.eigvalsh(spd)[:, -1, None, None] * np.eye(7)
    assert (ldl_pivots(spd) > 0).all()
    assert (ldl_pivots(indefinite).min(axis=1) <= 0).all()
