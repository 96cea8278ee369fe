"""The joint-space reference a controller follows."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError

Array = NDArray[np.float64]


class HasJointReference(Protocol):
    """Anything with ``t`` (N,) and ``q``, ``qd``, ``qdd`` (N, 7), such as an IK result."""

    @property
    def t(self) -> Array: ...

    @property
    def q(self) -> Array: ...

    @property
    def qd(self) -> Array: ...

    @property
    def qdd(self) -> Array: ...


@dataclass(frozen=True, eq=False)
class JointReference:
    """``q_d(t)``, ``qd_d(t)``, ``qdd_d(t)`` sampled at a uniform period.

    ``rates`` says how ``qd``, ``qdd`` were obtained: ``"exact"`` (differentiated optimality
    conditions) or ``"finite_difference"`` (the paper's numerical differentiation).
    """

    t: Array
    q: Array
    qd: Array
    qdd: Array
    rates: str = "exact"
    name: str = "reference"

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=float)
        if t.ndim != 1 or len(t) < 2:
            raise InputError(f"reference t must be 1-D with at least 2 samples, got shape {t.shape}")
        for label in ("q", "qd", "qdd"):
            value = np.asarray(getattr(self, label), dtype=float)
            if value.shape != (len(t), 7):
                raise InputError(f"reference {label} must have shape ({len(t)}, 7), got {value.shape}")
            if not np.isfinite(value).all():
                raise InputError(f"reference {label} must be finite")
        steps = np.diff(t)
        if not (steps > 0).all() or np.ptp(steps) > 1e-9 * steps.mean() + 1e-12:
            raise InputError("reference t must be strictly increasing with a uniform period")

    @property
    def dt(self) -> float:
        """Sampling period (s)."""
        return float((self.t[-1] - self.t[0]) / (len(self.t) - 1))

    @classmethod
    def of(cls, source: HasJointReference, name: str = "reference") -> JointReference:
        """Wrap an IK result (or any object with ``t``, ``q``, ``qd``, ``qdd``)."""
        if isinstance(source, JointReference):
            return source
        rates = getattr(source, "rates", "exact")
        return cls(
            np.asarray(source.t, dtype=float),
            np.asarray(source.q, dtype=float),
            np.asarray(source.qd, dtype=float),
            np.asarray(source.qdd, dtype=float),
            rates=str(rates),
            name=name,
        )
