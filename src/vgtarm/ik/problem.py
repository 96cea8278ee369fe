"""The optimisation problem of one inverse-kinematics sample (paper eq. 12), as plain arrays.

``min Phi(q) = (1/n) sum_i ((q_i - q_i*) / (q_i,max - q_i,min))^2`` with ``q* `` the middle of the
joint range and ``n = 7``, subject to the task's equality constraints (tip point, optionally the
orientation), the joint limits ``q_min <= q <= q_max`` and assemblability with a margin: the
triangle inequalities of the truss are linear in ``q`` (:func:`vgtarm.assembly.linear_form`), and
every sample must satisfy ``G q + h >= margin``. Rows that the joint limits already imply with
that margin are dropped, so the active-set systems stay small (for the reference robot only the two
``s + 2d > p`` rows remain).

Inequalities are ordered: 7 lower limits, 7 upper limits, then the kept triangle rows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from ..model.assembly import TRIANGLE_INEQUALITIES, linear_form
from ..model.parameters import JOINT_NAMES, RobotParameters

Array = NDArray[np.float64]

#: Default assembly margin (m): every triangle inequality holds with at least this slack.
DEFAULT_MARGIN = 5e-3


#: Largest ``rows * size(M)`` of one matrix product in :func:`rows_times` (OpenBLAS keeps products
#: below about ``2^18`` multiply-adds on the calling thread).
_BLOCK_WORK = 2**17


def rows_times(x: Array, M: Array) -> Array:
    """``x @ M.T`` for a batch ``x`` ``(n, c)`` and a small matrix ``M`` ``(r, c)``, as ``(n, r)``.

    Computed in blocks of rows small enough for OpenBLAS to run each product on the calling
    thread: one large product wakes OpenBLAS's thread pool, whose spinning threads then slow
    down the compiled model's OpenMP threads on the same cores (by a factor of about three for the
    batched rate evaluation on two cores).
    """
    n = x.shape[0]
    block = max(1, _BLOCK_WORK // max(1, M.size))
    if n <= block:
        return np.asarray(x @ M.T)
    out = np.empty((n, M.shape[0]))
    for start in range(0, n, block):
        out[start : start + block] = x[start : start + block] @ M.T
    return out


@dataclass(frozen=True, eq=False)
class IKProblem:
    """Cost, joint limits and linear inequalities of the redundancy resolution.

    Attributes:
        lower, upper: ``(7,)`` joint limits (m, rad).
        centre: ``(7,)`` middle of each range ``q*``.
        weight: ``(7,)`` diagonal of the constant Hessian of ``Phi``: ``2 / (7 (q_max - q_min)^2)``.
        G, h: ``(k, 7)``, ``(k,)`` kept triangle rows; the constraint is ``G q + h >= margin``.
        G_all, h_all: ``(12, 7)``, ``(12,)`` every triangle row (margins ``G_all q + h_all``),
            used to keep iterates assemblable.
        margin: Assembly margin (m).
        triangle_labels: ``(k,)`` names of the kept rows.
        A, b: ``(14 + k, 7)``, ``(14 + k,)`` every inequality as ``A q + b >= 0``, in the order of
            :attr:`constraint_labels`.
        active_scale: ``(14 + k,)`` factor ``c`` of the active-set rule ``mu - c * slack > 0``
            (the cost curvature of the joint the row moves), so that multipliers and slacks compare.
    """

    lower: Array
    upper: Array
    centre: Array
    weight: Array
    G: Array
    h: Array
    G_all: Array
    h_all: Array
    margin: float
    triangle_labels: tuple[str, ...]
    A: Array
    b: Array
    active_scale: Array

    @classmethod
    def from_parameters(cls, parameters: RobotParameters, margin: float = DEFAULT_MARGIN) -> IKProblem:
        """The problem of a robot, keeping the triangle rows that the joint limits do not imply."""
        if isinstance(margin, bool) or not isinstance(margin, int | float) or not math.isfinite(margin) or margin <= 0:
            raise InputError(
                f"margin must be a finite length > 0 (m), got {margin!r} (at zero margin the truss is flat and "
                "its kinematics are not differentiable)"
            )
        lower, upper = parameters.lower, parameters.upper
        G_all, h_all = linear_form(parameters.b, parameters.d)
        # Smallest value of each row over the box: the row is implied when it is >= margin.
        smallest = np.where(G_all > 0, G_all * lower, G_all * upper).sum(axis=1) + h_all
        keep = smallest < margin
        labels = tuple(
            f"module {row // 6 + 1}: {TRIANGLE_INEQUALITIES[row % 6]}" for row in np.flatnonzero(keep).tolist()
        )
        G, h = G_all[keep], h_all[keep]
        weight = 2.0 / (7.0 * (upper - lower) ** 2)
        return cls(
            lower=lower,
            upper=upper,
            centre=(lower + upper) / 2,
            weight=weight,
            G=G,
            h=h,
            G_all=G_all,
            h_all=h_all,
            margin=float(margin),
            triangle_labels=labels,
            A=np.concatenate([np.eye(7), -np.eye(7), G]),
            b=np.concatenate([-lower, upper, h - margin]),
            active_scale=np.concatenate([weight, weight, np.abs(G) @ weight / np.abs(G).sum(axis=1)]),
        )

    @property
    def n_triangle(self) -> int:
        """Number of kept triangle rows ``k``."""
        return int(self.G.shape[0])

    @property
    def constraint_labels(self) -> tuple[str, ...]:
        """Names of the ``14 + k`` inequalities, in their order."""
        return (
            tuple(f"{name} >= min" for name in JOINT_NAMES)
            + tuple(f"{name} <= max" for name in JOINT_NAMES)
            + tuple(f"{label} (margin {self.margin:g} m)" for label in self.triangle_labels)
        )

    def phi(self, q: Array) -> Array:
        """The cost ``Phi(q)`` of eq. 12, ``(...,)`` for ``q`` of shape ``(..., 7)``."""
        return np.asarray(0.5 * ((q - self.centre) ** 2 * self.weight).sum(axis=-1))

    def phi_gradient(self, q: Array) -> Array:
        """``dPhi/dq``, ``(..., 7)``."""
        return np.asarray(self.weight * (q - self.centre))

    def slacks(self, q: Array) -> Array:
        """Values of the ``14 + k`` inequalities (all ``>= 0`` when feasible), ``(..., 14 + k)`` (m, rad)."""
        flat = np.reshape(q, (-1, 7))
        return (rows_times(flat, self.A) + self.b).reshape(np.shape(q)[:-1] + (self.b.shape[0],))

    def assemblable(self, q: Array, margin: float = 0.0) -> NDArray[np.bool_]:
        """Whether every triangle row of ``q`` ``(..., 7)`` exceeds ``margin``."""
        flat = np.reshape(q, (-1, 7))
        inside = (rows_times(flat, self.G_all) + self.h_all > margin).all(axis=-1)
        return np.asarray(inside.reshape(np.shape(q)[:-1]))

    def feasible(self, q: Array, tolerance: float = 1e-12) -> NDArray[np.bool_]:
        """Whether ``q`` ``(..., 7)`` satisfies every inequality to ``tolerance``."""
        return np.asarray((self.slacks(q) >= -tolerance).all(axis=-1))
