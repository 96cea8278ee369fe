"""Verification of the KKT conditions of every sample (first and second order), batched.

A sample passes when

- its equality residual is at most ``tol_primal`` (m; rad-like for orientation rows),
- the Lagrangian gradient is at most ``tol_stationarity``,
- every inequality holds to ``tol_feasibility`` (joint limits, triangle rows with the margin),
- active rows have multipliers ``>= -tol_multiplier`` and inactive rows have zero multipliers,
- the Hessian of the Lagrangian is positive definite on the null space of the active
  constraints' Jacobian (second-order sufficient condition), certified by Gershgorin's bound or
  the pivots of an ``LDL^T`` factorisation done for the whole batch at once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from . import kkt
from .problem import IKProblem
from .state import BatchState

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Tolerances:
    """Acceptance thresholds of a verified sample."""

    primal: float = 1e-10
    stationarity: float = 1e-6
    feasibility: float = 1e-10
    multiplier: float = 1e-8
    curvature: float = 1e-10


@dataclass(frozen=True)
class Verification:
    """Per-sample KKT measures ``(n,)`` and the overall verdict."""

    primal: Array
    stationarity: Array
    violation: Array
    multiplier: Array
    curvature: Array
    passed: NDArray[np.bool_]


def ldl_pivots(M: Array) -> Array:
    """Pivots ``(n, r)`` of the ``LDL^T`` factorisation of symmetric ``M`` ``(n, r, r)``, without pivoting.

    ``M`` is positive definite exactly when every pivot is positive. Elimination stops being
    meaningful after a non-positive pivot; the later pivots of that sample are then arbitrary.
    """
    A = np.array(M, dtype=float, copy=True)
    r = A.shape[-1]
    pivots = np.empty(A.shape[:-1])
    for j in range(r):
        d = A[:, j, j]
        pivots[:, j] = d
        safe = np.where(d > 0, d, 1.0)
        column = A[:, j + 1 :, j] / safe[:, None]
        A[:, j + 1 :, j + 1 :] -= column[:, :, None] * A[:, j, j + 1 :][:, None, :]
    return pivots


def reduced_curvature(problem: IKProblem, W: Array, J: Array, active: NDArray[np.bool_]) -> Array:
    """A certificate ``(n,)`` of the second-order condition: positive exactly when it is verified.

    ``W`` ``(n, 7, 7)`` is the Hessian of the Lagrangian, ``J`` the task Jacobian and ``active``
    the active inequalities. Per sample, in order of cost: the Gershgorin lower bound of the
    smallest eigenvalue of ``W`` (when positive, every restriction of ``W`` is positive definite);
    else the smallest ``LDL^T`` pivot of ``W``; else the smallest pivot of ``P W P + c (I - P)``
    with ``P`` the projector onto the null space of the active constraints' Jacobian, which is
    positive definite exactly when the reduced Hessian is. Values are divided by the mean cost
    weight ``c``.
    """
    scale = float(problem.weight.mean())
    diagonal = np.diagonal(W, axis1=1, axis2=2)
    certificate = (diagonal - (np.abs(W).sum(axis=2) - np.abs(diagonal))).min(axis=1) / scale
    need = np.flatnonzero(~(certificate > 0))
    if need.size == 0:
        return certificate
    certificate[need] = ldl_pivots(W[need]).min(axis=1) / scale
    need = need[~(certificate[need] > 0)]
    if need.size == 0:
        return certificate
    n, m = need.size, J.shape[1]
    k = problem.n_triangle
    rows = np.zeros((n, m + 14 + k, 7))
    rows[:, :m] = J[need]
    rows[:, m:] = np.where(active[need][:, :, None], problem.A, 0.0)
    gram = rows @ rows.transpose(0, 2, 1)
    unused = ~np.concatenate([np.ones((n, m), dtype=bool), active[need]], axis=1)
    idx_n, idx_r = np.nonzero(unused)
    gram[idx_n, idx_r, idx_r] = 1.0  # rows of inactive constraints are zero: keep the Gram matrix regular
    projector = np.eye(7) - rows.transpose(0, 2, 1) @ np.linalg.solve(gram, rows)
    M = projector @ W[need] @ projector + scale * (np.eye(7) - projector)
    certificate[need] = ldl_pivots(M).min(axis=1) / scale
    return certificate


def verify(problem: IKProblem, state: BatchState, tolerances: Tolerances) -> Verification:
    """Check the KKT conditions of every sample from the solution and model values in ``state``."""
    q, lam, mu, active = state.q, state.lam, state.mu, state.active
    residual, J, H = state.residual, state.J, state.H
    primal = np.abs(residual).max(axis=1)
    stationarity = np.abs(kkt.stationarity(problem, q, J, lam, mu)).max(axis=1)
    violation = np.maximum(0.0, -problem.slacks(q)).max(axis=1)
    wrong_sign = np.where(active, np.maximum(0.0, -mu), np.abs(mu)).max(axis=1)
    curvature = reduced_curvature(problem, kkt.hessian(problem, H), J, active)
    with np.errstate(invalid="ignore"):
        passed = (
            (primal <= tolerances.primal)
            & (stationarity <= tolerances.stationarity)
            & (violation <= tolerances.feasibility)
            & (wrong_sign <= tolerances.multiplier)
            & (curvature > tolerances.curvature)
        )
    return Verification(primal, stationarity, violation, wrong_sign, curvature, passed)
