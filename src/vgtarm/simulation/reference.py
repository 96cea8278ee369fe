"""The joint-space reference a controller follows."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError, refuse_masked, shown
from ..model.parameters import N_JOINTS
from ..paths import MIN_DT

Array = NDArray[np.float64]


class HasJointReference(Protocol):
    """Anything with ``t`` (N,) and ``q``, ``qd``, ``qdd`` (N, n), such as an IK result."""

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

    ``tip`` ``(N, 3)`` is the desired tip path the joints were solved for (m; ``None``: unknown),
    ``robot`` and ``robot_fingerprint`` name the robot they were solved for (see
    :attr:`vgtarm.Robot.fingerprint`; "" if unknown). The simulator checks that the plant's
    kinematics put the tip of ``q`` on ``tip``, and names both robots when they do not.

    ``task`` is the IK task the joints were solved for (``"position"``, or a tool task: ``"axis"``,
    ``"entry point"``, ``"pose"``) and ``entry_point`` ``(3,)`` the point the tool's axis passes
    through (None: none); a run's summary then gives the tool's axis error and the axis' distance
    from the entry point.
    """

    t: Array
    q: Array
    qd: Array
    qdd: Array
    rates: str = "exact"
    name: str = "reference"
    tip: Array | None = None
    robot: str = ""
    robot_fingerprint: str = ""
    task: str = "position"
    entry_point: Array | None = None

    def __post_init__(self) -> None:
        t = _array(self.t, "t")
        if t.ndim != 1 or len(t) < 2:
            raise InputError(f"reference t must be 1-D with at least 2 samples, got shape {t.shape}")
        if not np.isfinite(t).all():
            raise InputError("reference t must be finite")
        width = np.shape(self.q)[-1] if np.ndim(self.q) == 2 else N_JOINTS  # any number of joints >= 1
        for label in ("q", "qd", "qdd"):
            value = _array(getattr(self, label), label)
            if value.shape != (len(t), width) or width < 1:
                raise InputError(f"reference {label} must have shape ({len(t)}, {width}), got {value.shape}")
            if not np.isfinite(value).all():
                row = int(np.argwhere(~np.isfinite(value))[0][0])
                raise InputError(f"reference {label} must be finite; row {row} (t = {t[row]:.6g} s) is not")
        if self.tip is not None:
            tip = _array(self.tip, "tip")
            if tip.shape != (len(t), 3) or not np.isfinite(tip).all():
                raise InputError(f"reference tip must be finite of shape ({len(t)}, 3), got shape {tip.shape}")
        steps = np.diff(t)
        if not (steps > 0).all() or np.ptp(steps) > 1e-9 * steps.mean() + 1e-12:
            raise InputError("reference t must be strictly increasing with a uniform period")
        if steps.mean() < MIN_DT:
            raise InputError(
                f"reference t: samples {steps.mean():.3g} s apart; at least {MIN_DT:g} s expected "
                "(shorter periods turn rounding into huge rates)"
            )

    @property
    def dt(self) -> float:
        """Sampling period (s)."""
        return float((self.t[-1] - self.t[0]) / (len(self.t) - 1))

    @classmethod
    def of(cls, source: HasJointReference, name: str | None = None) -> JointReference:
        """Wrap an IK result (or any object with ``t``, ``q``, ``qd``, ``qdd``).

        ``name`` defaults to the IK result's desired path's name (``path_name``), else ``"reference"``.

        An IK result also gives its desired tip path (``position``) and the robot it was solved
        for, which the simulator checks against the plant.
        """
        if isinstance(source, JointReference):
            return source
        missing = [label for label in ("t", "q", "qd", "qdd") if not hasattr(source, label)]
        if missing:
            raise InputError(
                f"reference = {shown(source)}: expected an IK result or a JointReference "
                f"(with t, q, qd, qdd), got a {type(source).__name__} without {', '.join(missing)}"
            )
        rates = getattr(source, "rates", "exact")
        position = getattr(source, "position", None)
        return cls(
            _array(source.t, "t"),
            _array(source.q, "q"),
            _array(source.qd, "qd"),
            _array(source.qdd, "qdd"),
            rates=str(rates),
            name=name if name is not None else _name_of(source, "path") or "reference",
            tip=None if position is None else _array(position, "tip"),
            robot=_name_of(source, "robot"),
            robot_fingerprint=str(getattr(source, "robot_fingerprint", "")),
            task=str(getattr(source, "task", "position")),
            entry_point=_optional(getattr(source, "entry_point", None), "entry_point"),
        )

    def head(self, n: int) -> JointReference:
        """The first ``n`` samples (``n >= 2``), with the same rates, name and robot."""
        return replace(
            self,
            t=self.t[:n],
            q=self.q[:n],
            qd=self.qd[:n],
            qdd=self.qdd[:n],
            tip=None if self.tip is None else self.tip[:n],
        )


def _optional(value: object, label: str) -> Array | None:
    """An IK result's optional array (its tool task's ``axis``, ``entry_point``), or None."""
    return None if value is None else _array(value, label)


def _name_of(source: object, what: str) -> str:
    """The name of the ``robot`` or ``path`` an IK result was solved for (its ``robot_name``,
    ``path_name``; a record of one's own may give the name as ``robot``, ``path``); "" if none."""
    name = getattr(source, f"{what}_name", None)
    if name is None:
        name = getattr(source, what, "")
    return name if isinstance(name, str) else ""


def _array(value: object, label: str) -> Array:
    """``value`` as a float array, or :class:`InputError` naming the reference's ``label`` (also a
    masked array with masked entries: np.asarray would take the values under the mask)."""
    refuse_masked(value, f"reference {label}")
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"reference {label} must be an array of numbers, got {shown(value)}") from None
