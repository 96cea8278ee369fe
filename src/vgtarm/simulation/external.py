"""External force on the tool (paper eq. 16)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .. import checks

Array = NDArray[np.float64]

#: Default smoothing speed (m/s) of the expected cutting force fed forward (a Scenario option):
#: measured choice in docs/control.md ("A reference that starts at rest, and the preset's loop").
DEFAULT_FEEDFORWARD_SPEED = 0.003


def expected_cutting_force(velocity: Array, force: float, speed: float) -> Array:
    """The cutting force's model along tip velocities ``velocity`` ``(..., 3)``, smoothed where the
    tool starts, turns or stops: ``-F0 (v/|v|) sigma^3``, ``sigma = |v| / sqrt(|v|^2 + v_s^2)``, i.e.
    ``-F0 v |v|^2 / (|v|^2 + v_s^2)^(3/2)`` with ``F0 = force`` (N) and ``v_s = speed`` (m/s).

    Far above ``v_s`` it is the cutting force ``-F0 v/|v|`` of eq. 16; from rest it grows with the
    cube of the speed, so its first and second time derivatives are zero where the tool rests: a
    reference or a feed-forward built on it starts at rest when the path does (the issue-22 model of
    before, ``-F0 v / sqrt(|v|^2 + v_s^2)``, had the slope ``-F0 a / v_s`` there). The one formula of
    the effort criterion's expected tool force (:mod:`vgtarm.ik.effort`, the same expression in
    CasADi) and of the feed-forward (:meth:`ExternalForce.expected`)."""
    v = np.asarray(velocity, dtype=float)
    squared = np.sum(v * v, axis=-1, keepdims=True)
    return -force * v * squared / (squared + speed * speed) ** 1.5


@dataclass(frozen=True)
class ExternalForce:
    """Cutting force ``-F0 V/|V|`` opposing the tip velocity plus a bounded random disturbance.

    Attributes:
        cutting: whether the cutting force acts.
        cutting_force: ``F0`` (N); paper: 20 N.
        cutting_speed: tip speed (m/s) below which the cutting force is zero (the tool does not
            cut while it rests); 1 mm/s by default.
        disturbance: whether the disturbance acts.
        eta: bounds (N) of the disturbance: each component uniform in ``[-eta_i, eta_i]``, drawn
            once per control period from a seeded generator; paper: (5, 5, 5) N.
    """

    cutting: bool = True
    cutting_force: float = 20.0
    cutting_speed: float = 1e-3
    disturbance: bool = True
    eta: tuple[float, float, float] = (5.0, 5.0, 5.0)

    def __post_init__(self) -> None:
        checks.number("cutting_force", self.cutting_force, minimum=0, unit="N")
        checks.number("cutting_speed", self.cutting_speed, minimum=0, unit="m/s")
        checks.vector("eta", self.eta, 3, minimum=0, unit="N")

    @classmethod
    def none(cls) -> ExternalForce:
        """No external force at all."""
        return cls(cutting=False, disturbance=False)

    @property
    def active(self) -> bool:
        """Whether any part acts."""
        return self.cutting or (self.disturbance and any(e > 0 for e in self.eta))

    def expected(self, velocity: Array, speed: float) -> Array:
        """The expected tool force ``(..., 3)`` along desired tip velocities ``velocity`` ``(..., 3)``:
        the cutting force's model with the disturbance's mean (zero), :func:`expected_cutting_force`
        smoothed over the speed ``v_s = speed`` (m/s) where the tool starts, turns or stops (the
        effort criterion's expected tool force, :mod:`vgtarm.ik.effort`); zeros without the cutting
        force."""
        v = np.asarray(velocity, dtype=float)
        if not self.cutting:
            return np.zeros(v.shape)
        return expected_cutting_force(v, self.cutting_force, speed)

    def disturbance_samples(self, n: int, rng: np.random.Generator) -> Array:
        """The disturbance at ``n`` control periods, ``(n, 3)`` (zeros when off)."""
        if not self.disturbance:
            return np.zeros((n, 3))
        return rng.uniform(-1.0, 1.0, size=(n, 3)) * np.asarray(self.eta)
