"""Joint rates and accelerations of the reference: exact (differentiated optimality) or finite differences.

**Exact.** Along the path the optimum satisfies ``F(q(t), lam(t), t) = 0`` with the KKT residual
``F = [grad Phi + J_c^T lam - A^T mu; c(q, t) - c_d(t)]`` and its active constraints held. With
the active set fixed, differentiating once and twice in time gives two linear systems with the
condensed KKT matrix ``K`` of :mod:`vgtarm.ik.kkt` at the solution:

- ``K [qd; lam_d; mu_d] = -dF/dt``, i.e. ``[0; xd]`` for the position task, so ``J_P qd = xd``;
- ``K [qdd; lam_dd; mu_dd] = -d^2/dt^2 F(q + t qd, lam + t lam_d, t)``, whose position rows read
  ``J_P qdd + Jdot_P qd = xdd``.

The second-order terms are obtained by automatic differentiation of the compiled KKT residual
(``jtimes`` of ``jtimes``, functions ``ik_*_d2``), never by hand. Rows of active limits and
triangle inequalities keep ``G qd = G qdd = 0``: where the active set changes along the path the
true rates jump, and the exact rates are those of the active set found at each sample.

**Finite differences** (the paper's numerical differentiation): ``qd`` by central differences of
the sampled ``q``, one-sided (Euler) at the first and last samples; ``qdd`` by the central second
difference inside and by one-sided differences of ``qd`` at the ends.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from . import kkt
from .problem import BatchState, IKProblem, Task

Array = NDArray[np.float64]
Index = NDArray[np.intp]

#: Names of the rate modes.
RATE_MODES = ("exact", "finite_difference")


def exact(problem: IKProblem, task: Task, state: BatchState, idx: Index) -> None:
    """Exact ``qd``, ``qdd`` (and ``lam_d``, ``lam_dd``) of the optimum along the path at samples ``idx``.

    ``state`` must hold the solution and the model values at it; the rates are stored in it.
    """
    nj = problem.n
    if idx.size == 0:
        return
    q, lam, active = state.q[idx], state.lam[idx], state.active[idx]
    m = task.m
    K = kkt.kkt_matrix(problem, kkt.hessian(problem, state.H[idx]), state.J[idx], active)
    first, _ = kkt.solve(K, kkt.rates_rhs(problem, task.first_order_rhs(idx, q, lam), active))
    qd, lam_d = first[:, :nj], first[:, nj : nj + m]
    second, _ = kkt.solve(K, kkt.rates_rhs(problem, task.second_order_rhs(idx, q, lam, qd, lam_d), active))
    qdd = second[:, :nj]
    on_bound = active[:, :nj] | active[:, nj : 2 * nj]
    qd[on_bound] = qdd[on_bound] = 0.0  # exact: these joints stay on their limits
    state.qd[idx], state.lam_d[idx] = qd, lam_d
    state.qdd[idx], state.lam_dd[idx] = qdd, second[:, nj : nj + m]
    state.rates_ready[idx] = True


def finite_difference(q: Array, dt: float) -> tuple[Array, Array]:
    """``qd``, ``qdd`` ``(N, n)`` of samples ``q`` ``(N, n)`` spaced by ``dt`` (central inside, Euler at the ends)."""
    qd = np.empty_like(q)
    qdd = np.empty_like(q)
    qd[1:-1] = (q[2:] - q[:-2]) / (2 * dt)
    qd[0] = (q[1] - q[0]) / dt
    qd[-1] = (q[-1] - q[-2]) / dt
    if q.shape[0] >= 3:
        qdd[1:-1] = (q[2:] - 2 * q[1:-1] + q[:-2]) / dt**2
        qdd[0] = (qd[1] - qd[0]) / dt
        qdd[-1] = (qd[-1] - qd[-2]) / dt
    else:
        qdd[:] = 0.0
    return qd, qdd
