"""The fixed-size KKT system of the active-set (semismooth) Newton method, for a batch of samples.

Per sample the unknowns are the joint step ``dq`` (7), the new equality multipliers ``lam`` (m)
and the new multipliers of the kept triangle rows ``mu_g`` (k); the multipliers of active joint
limits are eliminated. Every sample's matrix has the same size ``7 + m + k`` whatever its active
set, so the whole batch is one ``numpy.linalg.solve`` on an ``(n, 7 + m + k, 7 + m + k)`` array:

- row ``i < 7`` of a joint whose limit is active is replaced by ``dq_i = bound_i - q_i``; the
  other rows are the linearised stationarity ``W dq + J^T lam - G^T mu_g = -grad Phi``, with
  ``W = grad^2 Phi + d^2(lam^T c)/dq^2``;
- the ``m`` rows ``J dq = -(c - c_d)``;
- row ``l`` of a kept triangle inequality is ``G_l dq = -(G_l q + h_l - margin)`` when it is
  active and ``mu_g,l = 0`` when not.

The multiplier of an active limit then follows from its stationarity row (:func:`bound_multipliers`).
The same matrix, evaluated at the solution, gives the exact rates (:mod:`vgtarm.ik.rates`).

Inequality multipliers ``mu`` ``(n, 14 + k)`` and active flags are stored in the order of
:attr:`IKProblem.constraint_labels`: lower limits, upper limits, triangle rows; every ``mu >= 0``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .problem import IKProblem, rows_times

Array = NDArray[np.float64]
Mask = NDArray[np.bool_]


def hessian(problem: IKProblem, H: Array) -> Array:
    """``W = grad^2 Phi + H``, ``(n, 7, 7)``, for the constraint Hessian ``H`` ``(n, 7, 7)``."""
    W = H.copy()
    W[:, np.arange(7), np.arange(7)] += problem.weight
    return W


def kkt_matrix(problem: IKProblem, W: Array, J: Array, active: Mask) -> Array:
    """The condensed KKT matrix ``(n, 7 + m + k, 7 + m + k)`` for the active sets ``active`` ``(n, 14 + k)``."""
    n, m = J.shape[0], J.shape[1]
    k = problem.n_triangle
    size = 7 + m + k
    K = np.zeros((n, size, size))
    K[:, :7, :7] = W
    K[:, :7, 7 : 7 + m] = J.transpose(0, 2, 1)
    K[:, :7, 7 + m :] = -problem.G.T
    K[:, 7 : 7 + m, :7] = J
    box = active[:, :7] | active[:, 7:14]
    rows_n, rows_i = np.nonzero(box)
    K[rows_n, rows_i, :] = 0.0
    K[rows_n, rows_i, rows_i] = 1.0
    for row in range(k):
        on = active[:, 14 + row]
        K[on, 7 + m + row, :7] = problem.G[row]
        K[~on, 7 + m + row, 7 + m + row] = 1.0
    return K


def newton_rhs(problem: IKProblem, q: Array, residual: Array, active: Mask) -> Array:
    """Right-hand side ``(n, 7 + m + k)`` of the Newton step at ``q`` with equality residual ``residual``."""
    n, m = residual.shape
    k = problem.n_triangle
    rhs = np.zeros((n, 7 + m + k))
    rhs[:, :7] = -problem.phi_gradient(q)
    lower, upper = active[:, :7], active[:, 7:14]
    rhs[:, :7] = np.where(lower, problem.lower - q, rhs[:, :7])
    rhs[:, :7] = np.where(upper, problem.upper - q, rhs[:, :7])
    rhs[:, 7 : 7 + m] = -residual
    if k:
        slack = rows_times(q, problem.G) + problem.h - problem.margin
        rhs[:, 7 + m :] = np.where(active[:, 14:], -slack, 0.0)
    return rhs


def rates_rhs(problem: IKProblem, rhs_kkt: Array, active: Mask) -> Array:
    """Right-hand side ``(n, 7 + m + k)`` of a rate system from the path derivative of the KKT residual.

    ``rhs_kkt`` ``(n, 7 + m)`` is minus the derivative of ``[grad L; c - c_d]``; rows of active
    limits and triangle rows stay zero (the active constraints do not move), as do the
    multipliers of inactive rows.
    """
    n, size = rhs_kkt.shape
    rhs = np.zeros((n, size + problem.n_triangle))
    rhs[:, :size] = rhs_kkt
    box = active[:, :7] | active[:, 7:14]
    rhs[:, :7][box] = 0.0
    return rhs


def solve(K: Array, rhs: Array) -> tuple[Array, Mask]:
    """Solve every system ``K x = rhs``; returns ``x`` ``(n, s)`` and which samples were solvable.

    A singular matrix of one sample does not spoil the batch: its row is marked unsolvable (NaN).
    """
    try:
        return np.asarray(np.linalg.solve(K, rhs[..., None])[..., 0], dtype=float), np.ones(K.shape[0], dtype=bool)
    except np.linalg.LinAlgError:
        x = np.full(rhs.shape, np.nan)
        ok = np.zeros(K.shape[0], dtype=bool)
        for i in range(K.shape[0]):
            try:
                x[i] = np.linalg.solve(K[i], rhs[i])
                ok[i] = True
            except np.linalg.LinAlgError:
                pass
        return x, ok


def stationarity(problem: IKProblem, q: Array, J: Array, lam: Array, mu: Array) -> Array:
    """Gradient of the Lagrangian ``grad Phi + J^T lam - A^T mu`` ``(n, 7)`` (``A`` = inequality rows)."""
    return problem.phi_gradient(q) + np.einsum("nmi,nm->ni", J, lam) - rows_times(mu, problem.A.T)


def bound_multipliers(problem: IKProblem, q: Array, W: Array, J: Array, x: Array, active: Mask) -> Array:
    """All inequality multipliers ``(n, 14 + k)`` after a step ``x = (dq, lam, mu_g)`` of the condensed system."""
    m = J.shape[1]
    dq, lam, mu_g = x[:, :7], x[:, 7 : 7 + m], x[:, 7 + m :]
    r = problem.phi_gradient(q) + np.einsum("nij,nj->ni", W, dq) + np.einsum("nmi,nm->ni", J, lam)
    r -= rows_times(mu_g, problem.G.T)
    mu = np.zeros(active.shape)
    mu[:, :7] = np.where(active[:, :7], r, 0.0)
    mu[:, 7:14] = np.where(active[:, 7:14], -r, 0.0)
    mu[:, 14:] = np.where(active[:, 14:], mu_g, 0.0)
    return mu


def predict_active(problem: IKProblem, q: Array, mu: Array, active: Mask, tolerance: float) -> Mask:
    """Primal-dual active-set prediction ``mu - c * slack > 0`` with hysteresis ``tolerance``.

    A constraint enters the set when it is violated by more than ``tolerance`` (or its predicted
    multiplier says so) and leaves it when its multiplier is below ``-tolerance``.
    """
    slack = problem.slacks(q)
    scale = problem.active_scale
    indicator = mu - scale * slack
    enter = indicator > scale * tolerance
    stay = mu > -tolerance
    return np.where(active, stay, enter)
