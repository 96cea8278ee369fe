"""The inverse-kinematics solver interface: result records with work counters, and a registry
that takes a user's solver."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from vgtarm import paths
from vgtarm.errors import InputError
from vgtarm.ik import SOLVERS, in_place, inverse_kinematics, register_solver, solver_names, unregister_solver
from vgtarm.ik.problem import BatchState

PATH = paths.case2(dt=0.05)


@pytest.fixture(autouse=True)
def clean_registry():
    """Leave the registry as it was: solvers registered by a test are removed after it."""
    before = set(SOLVERS)
    yield
    for name in set(SOLVERS) - before:
        unregister_solver(name)


def test_built_in_solvers_return_records_with_work_counters(robot):
    result = inverse_kinematics(robot, PATH)
    assert result.success
    assert result.work["n_converged"] == len(PATH)
    assert result.work["n_evaluations"] >= len(PATH) and result.work["n_iterations"] >= 0
    assert result.work["wall_time_s"] > 0


def test_a_users_solver_is_called_and_its_counters_recorded(robot):
    calls: list[int] = []
    reference = SOLVERS["slsqp"]

    def wrapped(problem, task, q_start, options):
        calls.append(len(task))
        out = reference(problem, task, q_start, options)
        return dataclasses.replace(out, n_iterations=out.n_iterations + 1000)

    register_solver("wrapped_reference", wrapped, replace=True)
    assert "wrapped_reference" in solver_names()
    mine = inverse_kinematics(robot, PATH, solver="wrapped_reference")
    ref = inverse_kinematics(robot, PATH, solver="slsqp")
    assert calls == [len(PATH)] and mine.solver == "wrapped_reference"
    np.testing.assert_array_equal(mine.q, ref.q)
    assert mine.work["n_iterations"] == ref.work["n_iterations"] + 1000


def test_samples_a_users_solver_leaves_unsolved_are_recovered_and_verified(robot):
    """A solver that solves nothing: every sample falls back to the reference and is verified."""

    def lazy(problem, task, state: BatchState, q_start, options) -> None:
        state.q[:] = q_start  # a start, not a solution: converged stays False

    register_solver("lazy", in_place(lazy), replace=True)
    result = inverse_kinematics(robot, PATH, solver="lazy")
    assert result.success and result.work["n_converged"] == 0
    np.testing.assert_allclose(result.q, inverse_kinematics(robot, PATH, solver="slsqp").q, atol=1e-9)


def test_bad_registrations_and_results_are_refused(robot):
    with pytest.raises(InputError, match="'fast' is taken"):
        register_solver("fast", SOLVERS["fast"])
    with pytest.raises(InputError, match="expected a callable"):
        register_solver("not_callable", 42)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="expected a name"):
        register_solver("two words", SOLVERS["fast"])
    register_solver("broken", lambda problem, task, q_start, options: None, replace=True)  # type: ignore[arg-type,return-value]
    with pytest.raises(InputError, match="must return a SolverResult"):
        inverse_kinematics(robot, PATH, solver="broken")
    with pytest.raises(InputError, match="unknown inverse-kinematics solver 'nope'"):
        inverse_kinematics(robot, PATH, solver="nope")
    with pytest.raises(InputError, match="not a registered solver"):
        unregister_solver("fast")
