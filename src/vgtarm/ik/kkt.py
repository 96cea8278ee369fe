"""The fixed-size KKT system of the active-set (semismooth) Newton method, for a batch of samples.

Per sample the unknowns are the joint step ``dq`` (``nj``, the joints), the new equality multipliers ``lam`` (m)
and the new multipliers of the kept triangle rows ``mu_g`` (k); the multipliers of active joint
limits are eliminated. Every sample's matrix has the same size ``nj + m + k`` whatever its active
set, so the whole batch is one ``numpy.linalg.solve`` on an ``(n, nj + m + k, nj + m + k)`` array:

- row ``i < nj`` of a joint whose limit is active is replaced by ``dq_i = bound_i - q_i``; the
  other rows are the linearised stationarity ``W dq + J^T lam - G^T mu_g = -grad Phi``, with
  ``W = grad^2 Phi + d^2(lam^T c)/dq^2``;
- the ``m`` rows ``J dq = -(c - c_d)``;
- row ``l`` of a kept triangle inequality is ``G_l dq = -(G_l q + h_l - margin)`` when it is
  active and ``mu_g,l = 0`` when not.

The multiplier of an active limit then follows from its stationarity row (:func:`bound_multipliers`).
The same matrix, evaluated at the solution, gives the exact rates (:mod:`vgtarm.ik.rates`).

Inequality multipliers ``mu`` ``(n, 2 nj + k)`` and active flags are stored in the order of
:attr:`IKProblem.constraint_labels`: lower limits, upper limits, triangle rows; every ``mu >= 0``.

Multipliers and active sets of solutions found by other solvers (SLSQP, IPOPT), batched.

A reference solver returns ``q``; the KKT data the rates and the verification need are rebuilt
from it: constraints with slack below ``active_tolerance`` count as active, and the multipliers
are the least-squares solution of the stationarity condition ``grad Phi + J^T lam - A_act^T mu = 0``.

Verification of the KKT conditions of every sample (first and second order), batched.

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

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg
import scipy.linalg.lapack
from numpy.typing import NDArray

from .options import Tolerances
from .problem import BatchState, IKProblem, largest_magnitude, rows_times

Array = NDArray[np.float64]
Mask = NDArray[np.bool_]


def cost_gradient(problem: IKProblem, q: Array, g: Array | None = None) -> Array:
    """Gradient ``(n, nj)`` of the whole cost: ``grad Phi`` plus the model part ``g`` (effort criterion) if given."""
    gradient = problem.phi_gradient(q)
    return gradient if g is None else gradient + g


def hessian(problem: IKProblem, H: Array) -> Array:
    """``W = grad^2 Phi + H``, ``(n, nj, nj)``, for the constraint Hessian ``H`` ``(n, nj, nj)``."""
    nj = problem.n
    W = H.copy()
    W[:, np.arange(nj), np.arange(nj)] += problem.weight
    return W


def kkt_matrix(problem: IKProblem, W: Array, J: Array, active: Mask) -> Array:
    """The condensed KKT matrix ``(n, nj + m + k, nj + m + k)`` for the active sets ``active`` ``(n, 2 nj + k)``."""
    nj = problem.n
    n, m = J.shape[0], J.shape[1]
    k = problem.n_triangle
    size = nj + m + k
    K = np.zeros((n, size, size))
    K[:, :nj, :nj] = W
    K[:, :nj, nj : nj + m] = J.transpose(0, 2, 1)
    K[:, :nj, nj + m :] = -problem.G.T
    K[:, nj : nj + m, :nj] = J
    box = active[:, :nj] | active[:, nj : 2 * nj]
    rows_n, rows_i = np.nonzero(box)
    K[rows_n, rows_i, :] = 0.0
    K[rows_n, rows_i, rows_i] = 1.0
    for row in range(k):
        on = active[:, 2 * nj + row]
        K[on, nj + m + row, :nj] = problem.G[row]
        K[~on, nj + m + row, nj + m + row] = 1.0
    return K


def newton_rhs(problem: IKProblem, q: Array, residual: Array, active: Mask, g: Array | None = None) -> Array:
    """Right-hand side ``(n, nj + m + k)`` of the Newton step at ``q`` with equality residual ``residual``
    (``g``: the model part of the cost gradient, :func:`cost_gradient`)."""
    nj = problem.n
    n, m = residual.shape
    k = problem.n_triangle
    rhs = np.zeros((n, nj + m + k))
    rhs[:, :nj] = -cost_gradient(problem, q, g)
    lower, upper = active[:, :nj], active[:, nj : 2 * nj]
    rhs[:, :nj] = np.where(lower, problem.lower - q, rhs[:, :nj])
    rhs[:, :nj] = np.where(upper, problem.upper - q, rhs[:, :nj])
    rhs[:, nj : nj + m] = -residual
    if k:
        slack = rows_times(q, problem.G) + problem.h - problem.margin
        rhs[:, nj + m :] = np.where(active[:, 2 * nj :], -slack, 0.0)
    return rhs


def rates_rhs(problem: IKProblem, rhs_kkt: Array, active: Mask) -> Array:
    """Right-hand side ``(n, nj + m + k)`` of a rate system from the path derivative of the KKT residual.

    ``rhs_kkt`` ``(n, nj + m)`` is minus the derivative of ``[grad L; c - c_d]``; rows of active
    limits and triangle rows stay zero (the active constraints do not move), as do the
    multipliers of inactive rows.
    """
    nj = problem.n
    n, size = rhs_kkt.shape
    rhs = np.zeros((n, size + problem.n_triangle))
    rhs[:, :size] = rhs_kkt
    box = active[:, :nj] | active[:, nj : 2 * nj]
    rhs[:, :nj][box] = 0.0
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


def stationarity(problem: IKProblem, q: Array, J: Array, lam: Array, mu: Array, g: Array | None = None) -> Array:
    """Gradient of the Lagrangian ``grad Phi + J^T lam - A^T mu`` ``(n, nj)`` (``A`` = inequality rows)."""
    out = cost_gradient(problem, q, g)  # a new array: the sum is formed in it, left to right
    out += np.einsum("nmi,nm->ni", J, lam)
    out -= rows_times(mu, problem.A.T)
    return out


def bound_multipliers(
    problem: IKProblem, q: Array, W: Array, J: Array, x: Array, active: Mask, g: Array | None = None
) -> Array:
    """All inequality multipliers ``(n, 2 nj + k)`` after a step ``x = (dq, lam, mu_g)`` of the condensed system."""
    nj = problem.n
    m = J.shape[1]
    dq, lam, mu_g = x[:, :nj], x[:, nj : nj + m], x[:, nj + m :]
    r = cost_gradient(problem, q, g) + np.einsum("nij,nj->ni", W, dq) + np.einsum("nmi,nm->ni", J, lam)
    r -= rows_times(mu_g, problem.G.T)
    mu = np.zeros(active.shape)
    mu[:, :nj] = np.where(active[:, :nj], r, 0.0)
    mu[:, nj : 2 * nj] = np.where(active[:, nj : 2 * nj], -r, 0.0)
    mu[:, 2 * nj :] = np.where(active[:, 2 * nj :], mu_g, 0.0)
    return mu


def predict_active(problem: IKProblem, q: Array, mu: Array, active: Mask, tolerance: float) -> Mask:
    """Primal-dual active-set prediction ``mu - c * slack > 0`` with hysteresis ``tolerance``.

    A constraint enters the set when it is violated by more than ``tolerance`` (or its predicted
    multiplier says so) and leaves it when its multiplier is below ``-tolerance``.
    """
    scale = problem.active_scale
    indicator = problem.slacks(q)  # a new array: mu - scale * slack is formed in it
    indicator *= scale
    np.subtract(mu, indicator, out=indicator)
    enter = indicator > scale * tolerance
    stay = mu > -tolerance
    return np.where(active, stay, enter)


def estimate_multipliers(
    problem: IKProblem, q: Array, J: Array, active_tolerance: float, g: Array | None = None
) -> tuple[Array, Array, NDArray[np.bool_]]:
    """``lam`` ``(n, m)``, ``mu`` ``(n, 2 nj + k)`` and active flags of solutions ``q`` ``(n, nj)``."""
    n, m = J.shape[0], J.shape[1]
    active = problem.slacks(q) <= active_tolerance
    A = problem.A
    columns = np.concatenate([J.transpose(0, 2, 1), -np.where(active[:, None, :], A.T, 0.0)], axis=2)
    normal = columns.transpose(0, 2, 1) @ columns
    unused = np.concatenate([np.zeros((n, m), dtype=bool), ~active], axis=1)
    rows, cols = np.nonzero(unused)
    normal[rows, cols, cols] = 1.0
    rhs = -np.einsum("nij,ni->nj", columns, cost_gradient(problem, q, g))
    y, _ = solve(normal, rhs)
    return y[:, :m], np.where(active, y[:, m:], 0.0), active


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
    with np.errstate(over="ignore", invalid="ignore"):  # after a bad pivot (large r): arbitrary values
        for j in range(r):
            d = A[:, j, j]
            pivots[:, j] = d
            safe = np.where(d > 0, d, 1.0)
            column = A[:, j + 1 :, j] / safe[:, None]
            A[:, j + 1 :, j + 1 :] -= column[:, :, None] * A[:, j, j + 1 :][:, None, :]
    return pivots


def reduced_curvature(problem: IKProblem, W: Array, J: Array, active: NDArray[np.bool_]) -> Array:
    """A certificate ``(n,)`` of the second-order condition: positive exactly when it is verified.

    ``W`` ``(n, nj, nj)`` is the Hessian of the Lagrangian, ``J`` the task Jacobian and ``active``
    the active inequalities. Per sample, in order of cost: the Gershgorin lower bound of the
    smallest eigenvalue of ``W`` (when positive, every restriction of ``W`` is positive definite);
    else the smallest ``LDL^T`` pivot of ``W``; else the smallest pivot of ``P W P + c (I - P)``
    with ``P`` the projector onto the null space of the active constraints' Jacobian, which is
    positive definite exactly when the reduced Hessian is. Values are divided by the mean cost
    weight ``c``.
    """
    scale = float(problem.weight.mean())
    certificate = _gershgorin(W) / scale
    need = np.flatnonzero(~(certificate > 0))
    if need.size == 0:
        return certificate
    if problem.n >= LAPACK_FROM:
        return _curvature_lapack(problem, W, J, active, certificate, need, scale)
    certificate[need] = _beyond_gershgorin(problem, W[need], J[need], active[need], scale)
    return certificate


def _gershgorin(W: Array) -> Array:
    """Gershgorin's lower bound ``(n,)`` of the smallest eigenvalue of each symmetric ``W`` ``(n, r, r)``."""
    diagonal = np.diagonal(W, axis1=1, axis2=2)
    return np.asarray((diagonal - (np.abs(W).sum(axis=2) - np.abs(diagonal))).min(axis=1))


def _beyond_gershgorin(problem: IKProblem, W: Array, J: Array, active: NDArray[np.bool_], scale: float) -> Array:
    """:func:`reduced_curvature` of samples whose Gershgorin bound is not positive (fewer than
    :data:`LAPACK_FROM` joints): the smallest ``LDL^T`` pivot of ``W``, else that of ``P W P + c (I - P)``."""
    nj = problem.n
    certificate = ldl_pivots(W).min(axis=1) / scale
    need = np.flatnonzero(~(certificate > 0))
    if need.size == 0:
        return certificate
    n, m = need.size, J.shape[1]
    k = problem.n_triangle
    rows = np.zeros((n, m + 2 * nj + k, nj))
    rows[:, :m] = J[need]
    rows[:, m:] = np.where(active[need][:, :, None], problem.A, 0.0)
    gram = rows @ rows.transpose(0, 2, 1)
    unused = ~np.concatenate([np.ones((n, m), dtype=bool), active[need]], axis=1)
    idx_n, idx_r = np.nonzero(unused)
    gram[idx_n, idx_r, idx_r] = 1.0  # rows of inactive constraints are zero: keep the Gram matrix regular
    try:
        through = np.linalg.solve(gram, rows)
    except np.linalg.LinAlgError:  # dependent task rows (a planar robot's tip: one row is zero)
        through = np.linalg.pinv(gram, hermitian=True) @ rows
    projector = np.eye(nj) - rows.transpose(0, 2, 1) @ through
    M = projector @ W[need] @ projector + scale * (np.eye(nj) - projector)
    certificate[need] = ldl_pivots(M).min(axis=1) / scale
    return certificate


#: Bytes of the Hessians whose Gershgorin bounds :func:`verify` computes at once (a few hundred kB:
#: the temporaries stay in the cache and in memory the allocator keeps; each bound is its own row's).
GERSHGORIN_BLOCK_BYTES = 256 * 2**10


def _certify(problem: IKProblem, H: Array, J: Array, active: NDArray[np.bool_]) -> Array:
    """:func:`reduced_curvature` of ``hessian(problem, H)``, the same values, with the Hessians made
    and bounded :data:`GERSHGORIN_BLOCK_BYTES` at a time (the later stages see the same samples together)."""
    nj = problem.n
    scale = float(problem.weight.mean())
    certificate = np.empty(H.shape[0])
    step = max(1, GERSHGORIN_BLOCK_BYTES // (8 * nj * nj))
    for start in range(0, H.shape[0], step):
        part = slice(start, start + step)
        W = hessian(problem, H[part])
        certificate[part] = _gershgorin(W) / scale
        if nj >= LAPACK_FROM:  # per sample: the same in any block
            need = np.flatnonzero(~(certificate[part] > 0))
            if need.size:
                _curvature_lapack(problem, W, J[part], active[part], certificate[part], need, scale)
    if nj < LAPACK_FROM:
        need = np.flatnonzero(~(certificate > 0))
        if need.size:
            W = hessian(problem, H[need])
            certificate[need] = _beyond_gershgorin(problem, W, J[need], active[need], scale)
    return certificate


#: From this many joints on (a long stack), :func:`reduced_curvature` factorises each sample's matrix
#: with LAPACK's Cholesky (``dpotrf``: the pivots are the squares of its diagonal) and projects with an
#: orthonormal basis of the active rows only, instead of the vectorised ``LDL^T`` loop in NumPy and
#: the projector through the Gram matrix of every inequality row: the same certificate, ``O(n^3 / 3)``
#: per sample in compiled code. Below it (the paper's robot) the NumPy loop is faster, and unchanged.
LAPACK_FROM = 30


def _smallest_pivot(matrix: Array) -> float:
    """The smallest ``LDL^T`` pivot of a symmetric matrix: from LAPACK's Cholesky when it is positive
    definite, else from :func:`ldl_pivots` (then it is <= 0, or not a number)."""
    factor, info = scipy.linalg.lapack.dpotrf(matrix, lower=0, clean=0)
    if info == 0:
        return float(np.diagonal(factor).min() ** 2)
    return float(ldl_pivots(matrix[None].copy()).min())


def _curvature_lapack(
    problem: IKProblem,
    W: Array,
    J: Array,
    active: NDArray[np.bool_],
    certificate: Array,
    need: NDArray[np.intp],
    scale: float,
) -> Array:
    """:func:`reduced_curvature`'s second and third stages, per sample with LAPACK (:data:`LAPACK_FROM`)."""
    nj = problem.n
    for i in need.tolist():
        factor, info = scipy.linalg.lapack.dpotrf(W[i], lower=0, clean=0)
        if info == 0:  # W positive definite: its smallest pivot is the certificate
            certificate[i] = float(np.diagonal(factor).min() ** 2) / scale
            continue
        # W is not positive definite: its pivots (an O(n^3) loop in NumPy) would only say so; go to
        # the reduced Hessian at once
        rows = np.concatenate([J[i], problem.A[active[i]]])
        basis, r, _ = scipy.linalg.qr(rows.T, mode="economic", pivoting=True)
        rank = int((np.abs(np.diagonal(r)) > 1e-12 * max(1.0, float(np.abs(r).max()))).sum())
        Q = basis[:, :rank]  # orthonormal basis of the span of the active rows; P = I - Q Q^T
        WQ = W[i] @ Q
        M = W[i] - Q @ WQ.T - WQ @ Q.T + Q @ (Q.T @ WQ) @ Q.T + scale * (Q @ Q.T)
        certificate[i] = _smallest_pivot((M + M.T) / 2) / scale
    assert certificate.shape[0] == W.shape[0] and nj == W.shape[1]
    return certificate


#: Bytes of the Hessians that :func:`verify` certifies at once (each sample's certificate is its own:
#: blocks only spare a long arm's arrays of gigabytes, 1.5 GB for the 50-module arm's 6,284 samples).
CURVATURE_BLOCK_BYTES = 64 * 2**20


#: Rows of :func:`verify`'s per-sample measures taken at once: the temporaries of a block stay small
#: (tens of kB, in the cache and in memory the allocator keeps) where those of a whole path (megabytes)
#: would be mapped afresh, and written through page faults, for every operation.
ROW_BLOCK = 1024


def _row_maxima(function: Callable[..., Array], *arrays: NDArray[Any]) -> Array:
    """``function(*arrays).max(axis=1)`` ``(n,)`` for an elementwise ``function`` of row arrays ``(n, ...)``,
    :data:`ROW_BLOCK` rows at a time (each row's maximum is its own: the same values)."""
    n = arrays[0].shape[0]
    out = np.empty(n)
    for start in range(0, n, ROW_BLOCK):
        part = slice(start, start + ROW_BLOCK)
        out[part] = function(*(a[part] for a in arrays)).max(axis=1)
    return out


def _shortfall(slack: Array) -> Array:
    """How far each inequality is violated, ``max(0, -slack)``."""
    return np.maximum(0.0, -slack)


def _wrong_sign(active: Mask, mu: Array) -> Array:
    """A multiplier's error of sign: ``max(0, -mu)`` on an active row, ``|mu|`` on an inactive one."""
    return np.where(active, np.maximum(0.0, -mu), np.abs(mu))


def verify(problem: IKProblem, state: BatchState, tolerances: Tolerances) -> Verification:
    """Check the KKT conditions of every sample from the solution and model values in ``state``."""
    q, lam, mu, active = state.q, state.lam, state.mu, state.active
    residual, J, H = state.residual, state.J, state.H
    primal = largest_magnitude(residual)
    gradient = largest_magnitude(stationarity(problem, q, J, lam, mu, state.g))
    violation = _row_maxima(_shortfall, problem.slacks(q))
    wrong_sign = _row_maxima(_wrong_sign, active, mu)
    curvature = np.empty(q.shape[0])
    block = max(1, CURVATURE_BLOCK_BYTES // (8 * problem.n * problem.n))  # the paper's robot: one block
    for start in range(0, q.shape[0], block):
        part = slice(start, start + block)
        curvature[part] = _certify(problem, H[part], J[part], active[part])
    with np.errstate(invalid="ignore"):
        passed = (
            (primal <= tolerances.primal)
            & (gradient <= tolerances.stationarity)
            & (violation <= tolerances.feasibility)
            & (wrong_sign <= tolerances.multiplier)
            & (curvature > tolerances.curvature)
        )
    return Verification(primal, gradient, violation, wrong_sign, curvature, passed)
