"""Multipliers and active sets of solutions found by other solvers (SLSQP, IPOPT), batched.

A reference solver returns ``q``; the KKT data the rates and the verification need are rebuilt
from it: constraints with slack below ``active_tolerance`` count as active, and the multipliers
are the least-squares solution of the stationarity condition ``grad Phi + J^T lam - A_act^T mu = 0``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from . import kkt
from .problem import IKProblem

Array = NDArray[np.float64]


def estimate(problem: IKProblem, q: Array, J: Array, active_tolerance: float) -> tuple[Array, Array, NDArray[np.bool_]]:
    """``lam`` ``(n, m)``, ``mu`` ``(n, 14 + k)`` and active flags of solutions ``q`` ``(n, 7)``."""
    n, m = J.shape[0], J.shape[1]
    active = problem.slacks(q) <= active_tolerance
    A = problem.A
    columns = np.concatenate([J.transpose(0, 2, 1), -np.where(active[:, None, :], A.T, 0.0)], axis=2)
    normal = columns.transpose(0, 2, 1) @ columns
    unused = np.concatenate([np.zeros((n, m), dtype=bool), ~active], axis=1)
    rows, cols = np.nonzero(unused)
    normal[rows, cols, cols] = 1.0
    rhs = -np.einsum("nij,ni->nj", columns, problem.phi_gradient(q))
    y, _ = kkt.solve(normal, rhs)
    return y[:, :m], np.where(active, y[:, m:], 0.0), active
