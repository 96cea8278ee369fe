"""The computed-force law in NumPy, once: every Python path calls these two functions.

The compiled loop evaluates the same law generated from the one symbolic definition
(``vgt_cfc`` of :mod:`vgtarm.model.codegen.control`); the tests hold the two to each other.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]


def commanded_acceleration(qdd_d: ArrayLike, e: ArrayLike, e_dot: ArrayLike, Kp: ArrayLike, Kv: ArrayLike) -> Array:
    """``qdd_d + Kp e + Kv e_dot`` (paper eq. 19), batched over leading axes.

    ``qdd_d``, ``e``, ``e_dot``: ``(..., n)``; ``Kp``, ``Kv``: ``(n, n)`` or ``(..., n, n)``.
    """
    kp, kv = np.asarray(Kp, dtype=float), np.asarray(Kv, dtype=float)
    e_a, ed_a = np.asarray(e, dtype=float), np.asarray(e_dot, dtype=float)
    return np.asarray(qdd_d, dtype=float) + (kp @ e_a[..., None])[..., 0] + (kv @ ed_a[..., None])[..., 0]


def computed_force(
    M: ArrayLike,
    C: ArrayLike,
    qdd_d: ArrayLike,
    e: ArrayLike,
    e_dot: ArrayLike,
    Kp: ArrayLike,
    Kv: ArrayLike,
    tau_ext_hat: ArrayLike | None = None,
) -> Array:
    """Computed force control, paper eq. 20: ``F = M^ (qdd_d + Kp e + Kv e_dot) + C^ - tau_ext_hat``.

    ``M``, ``C``: the controller's model at the measured state; ``tau_ext_hat``: an estimate of the
    external joint efforts to cancel (a disturbance observer's), default none.
    """
    a = commanded_acceleration(qdd_d, e, e_dot, Kp, Kv)
    F = (np.asarray(M, dtype=float) @ a[..., None])[..., 0] + np.asarray(C, dtype=float)
    if tau_ext_hat is not None:
        F = F - np.asarray(tau_ext_hat, dtype=float)
    return F
