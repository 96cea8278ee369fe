"""Computed force control (paper eqs. 18-20)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError, shown
from ..model.parameters import N_JOINTS
from ..model.robot import Robot
from .gains import Gains
from .law import computed_force

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ComputedForceControl:
    """``F = M^(q) [qdd_d + Kp e + Kv e_dot] + C^(q, qd)``, ``e = q_d - q``, with fixed gains.

    ``M^``, ``C^`` come from the controller's own model, which the simulator lets differ from
    the plant's. The controller does not know the external force.
    """

    gains: Gains
    name: str = field(default="cfc")

    def __post_init__(self) -> None:
        if not isinstance(self.gains, Gains):
            raise InputError(f"gains = {shown(self.gains)}: expected Gains (use ComputedForceControl.with_gains)")

    @classmethod
    def with_gains(cls, Kp: ArrayLike, Kv: ArrayLike, n_joints: int = N_JOINTS) -> ComputedForceControl:
        """Controller of a robot with ``n_joints`` joints (default the paper's 7) with gains from
        scalars (times the identity), diagonals or matrices."""
        return cls(Gains.of(Kp, Kv, n_joints))

    def effort(
        self,
        model: Robot,
        q: ArrayLike,
        qd: ArrayLike,
        q_d: ArrayLike,
        qd_d: ArrayLike,
        qdd_d: ArrayLike,
        gains: Gains | None = None,
    ) -> Array:
        """Actuator efforts ``(..., n)`` for states and references ``(..., n)`` (eq. 20)."""
        g = gains or self.gains
        e = np.asarray(q_d, dtype=float) - np.asarray(q, dtype=float)
        e_dot = np.asarray(qd_d, dtype=float) - np.asarray(qd, dtype=float)
        return computed_force(model.mass_matrix(q), model.bias_forces(q, qd), qdd_d, e, e_dot, g.Kp, g.Kv)
