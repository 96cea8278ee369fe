"""The working arrays of a batch of inverse-kinematics samples (primal, dual, active set, last model values)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


@dataclass
class BatchState:
    """Mutable per-sample arrays, all with ``N`` rows, updated in place by the solvers.

    Attributes:
        q: ``(N, 7)`` joint values.
        lam: ``(N, m)`` multipliers of the equality rows.
        mu: ``(N, 14 + k)`` multipliers of the inequalities (>= 0), in the problem's order.
        active: ``(N, 14 + k)`` active flags of the inequalities.
        residual, J, H: ``(N, m)``, ``(N, m, 7)``, ``(N, 7, 7)`` task residual, Jacobian and
            ``d^2(lam^T c)/dq^2`` at ``(q, lam)`` (valid where ``evaluated``).
        iterations: ``(N,)`` Newton (or solver) iterations spent on each sample.
        converged: ``(N,)`` whether the sample met the Newton stopping test.
        method: ``(N,)`` name of the method that produced each sample.
        qd, qdd, lam_d, lam_dd: exact rates of ``q`` and ``lam`` where ``rates_ready``.
        rates_ready: ``(N,)`` whether the exact rates of a sample are computed.
    """

    q: Array
    lam: Array
    mu: Array
    active: NDArray[np.bool_]
    residual: Array
    J: Array
    H: Array
    iterations: NDArray[np.int64]
    converged: NDArray[np.bool_]
    method: NDArray[np.str_]
    qd: Array
    qdd: Array
    lam_d: Array
    lam_dd: Array
    rates_ready: NDArray[np.bool_]

    @classmethod
    def empty(cls, n: int, m: int, n_inequalities: int) -> BatchState:
        return cls(
            q=np.zeros((n, 7)),
            lam=np.zeros((n, m)),
            mu=np.zeros((n, n_inequalities)),
            active=np.zeros((n, n_inequalities), dtype=bool),
            residual=np.full((n, m), np.nan),
            J=np.full((n, m, 7), np.nan),
            H=np.full((n, 7, 7), np.nan),
            iterations=np.zeros(n, dtype=np.int64),
            converged=np.zeros(n, dtype=bool),
            method=np.full(n, "", dtype="<U24"),
            qd=np.zeros((n, 7)),
            qdd=np.zeros((n, 7)),
            lam_d=np.zeros((n, m)),
            lam_dd=np.zeros((n, m)),
            rates_ready=np.zeros(n, dtype=bool),
        )
