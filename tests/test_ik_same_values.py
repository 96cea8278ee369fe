"""The inverse kinematics' cheaper forms of the same arithmetic give the same values, bit for bit.

Issue 35: the row reductions of narrow arrays column by column, the verification's curvature
certificates computed in blocks, and the Newton iteration that stores the model values only where a
sample leaves it. Each is checked here against the plain formula it replaces (NumPy's reductions,
:func:`vgtarm.ik.kkt.reduced_curvature` of the whole batch, a loop that stores every evaluation).
"""

from __future__ import annotations

import numpy as np
import pytest

import vgtarm
from vgtarm import paths
from vgtarm.ik import kkt, newton
from vgtarm.ik.options import NewtonSettings
from vgtarm.ik.problem import BatchState, IKProblem, largest_magnitude, rows_all, rows_any
from vgtarm.ik.solve import _task


@pytest.fixture(scope="module")
def robot() -> vgtarm.Robot:
    return vgtarm.load_robot()


@pytest.mark.parametrize("width", [1, 2, 3, 7, 16, 17, 40])
def test_row_reductions_equal_numpys(width: int) -> None:
    rng = np.random.default_rng(width)
    x = rng.standard_normal((257, width)) * 10.0 ** rng.integers(-300, 300, size=(257, width))
    x[::5, 0] = -0.0
    x[::7] = 0.0
    x[3, -1], x[4, 0], x[5, width // 2] = np.nan, np.inf, -np.inf
    expected = np.abs(x).max(axis=1)
    got = largest_magnitude(x)
    assert np.array_equal(got, expected, equal_nan=True)
    assert not np.signbit(got[np.isfinite(got)]).any()  # every maximum of magnitudes is >= +0
    mask = rng.random((257, width)) < 0.8
    mask[::3] = True
    mask[::4] = False
    assert np.array_equal(rows_all(mask), mask.all(axis=1))
    assert np.array_equal(rows_any(mask), mask.any(axis=1))
    assert largest_magnitude(x[:0]).shape == rows_all(mask[:0]).shape == (0,)


def _hessians(problem: IKProblem, n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Constraint Hessians ``H`` (some making ``W`` indefinite), Jacobians and active sets."""
    rng = np.random.default_rng(seed)
    nj = problem.n
    A = rng.standard_normal((n, nj, nj))
    H = 0.5 * (A + A.transpose(0, 2, 1)) * rng.choice([1e-2, 1.0, 100.0], size=(n, 1, 1))
    J = rng.standard_normal((n, 3, nj))
    active = rng.random((n, 2 * nj + problem.n_triangle)) < 0.1
    active[:, nj : 2 * nj] &= ~active[:, :nj]  # a joint on one limit at a time
    return H, J, active


@pytest.mark.parametrize("lapack", [False, True])
def test_certificates_in_blocks_equal_the_whole_batch(robot, monkeypatch, lapack: bool) -> None:
    """:func:`kkt._certify` in blocks of a few samples against :func:`kkt.reduced_curvature` of the whole
    batch, through every stage: Gershgorin's bound, the pivots of ``W`` and of the projected matrix."""
    problem = IKProblem.from_parameters(robot.parameters)
    H, J, active = _hessians(problem, 300, 1)
    if lapack:
        monkeypatch.setattr(kkt, "LAPACK_FROM", 1)
    whole = kkt.reduced_curvature(problem, kkt.hessian(problem, H), J, active)
    assert (whole > 0).any() and (whole <= 0).any()  # both verdicts occur
    scale = float(problem.weight.mean())
    gershgorin = kkt._gershgorin(kkt.hessian(problem, H)) / scale
    assert (gershgorin <= 0).sum() > (whole <= 0).sum()  # the later stages are reached
    monkeypatch.setattr(kkt, "GERSHGORIN_BLOCK_BYTES", 8 * problem.n**2 * 7)  # blocks of 7 samples
    assert np.array_equal(kkt._certify(problem, H, J, active), whole)


def _iterate_storing_every_evaluation(problem, task, state, idx, settings):
    """:func:`newton.iterate` as it was: every evaluation's model values stored at once."""
    evaluate = newton._evaluate

    def evaluate_and_store(task, working, q, lam, weight, in_call):
        out = evaluate(task, working, q, lam, weight, in_call)
        newton._store_model(state, working, None, out[:4])
        return out

    newton._evaluate = evaluate_and_store
    try:
        return newton.iterate(problem, task, state, idx, settings, with_rates=True, curvature=True)
    finally:
        newton._evaluate = evaluate


@pytest.mark.parametrize("max_iterations", [2, 4, 30])
def test_newton_keeps_the_model_values_of_each_samples_last_iterate(robot, max_iterations: int) -> None:
    """From a poor start (samples that stop at different steps, or run out of steps), the state after
    :func:`newton.iterate` equals that of the loop that stores every evaluation."""
    path = paths.case1(dt=0.05)
    problem = IKProblem.from_parameters(robot.parameters)
    task = _task(robot, path, None)
    idx = np.arange(len(path), dtype=np.intp)
    settings = NewtonSettings(max_iterations=max_iterations)
    states = []
    for run in (newton.iterate, _iterate_storing_every_evaluation):
        state = BatchState.empty(len(path), task.m, 2 * problem.n + problem.n_triangle, problem.n)
        state.q[:] = robot.parameters.home
        if run is newton.iterate:
            run(problem, task, state, idx, settings, with_rates=True, curvature=True)
        else:
            run(problem, task, state, idx, settings)
        states.append(state)
    new, old = states
    stopped = int(new.converged.sum())
    assert {2: stopped == 0, 4: 0 < stopped < len(path), 30: stopped == len(path)}[max_iterations]
    for name in ("q", "lam", "mu", "active", "residual", "J", "H", "iterations", "converged", "qd", "qdd"):
        assert np.array_equal(getattr(new, name), getattr(old, name), equal_nan=True), name
