"""Desired end-effector orientations for the full-pose variant of inverse kinematics.

With the orientation given as well as the tip point, six equations remain for seven joints: one
degree of redundancy (the heave shared by the two modules) is left to the cost ``Phi``. The
orientation residual is ``e = 0.5 vee(R_d^T R - R^T R_d)``, ``|e| = sin(angle)``; since it also
vanishes at a half turn, every solution's true angle error is checked separately.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError

Array = NDArray[np.float64]

#: Largest deviation of ``R^T R`` from the identity for a matrix to count as a rotation.
ORTHONORMAL_TOLERANCE = 1e-9

#: The ``pose`` value that holds the free-orientation optimum of the first sample.
HOLD = "hold"


@dataclass(frozen=True, eq=False)
class OrientationPath:
    """Desired end-effector orientation ``C03`` along a path.

    Attributes:
        rotation: ``(3, 3)`` (held constant) or ``(N, 3, 3)`` (one per sample) rotation matrices.
        angular_velocity: ``(N, 3)`` angular velocity of the target in F0 (rad/s); default zero
            for a constant rotation. Needed by the exact rates of a changing orientation.
        angular_acceleration: ``(N, 3)`` its derivative (rad/s^2), likewise.
    """

    rotation: ArrayLike
    angular_velocity: ArrayLike | None = None
    angular_acceleration: ArrayLike | None = None


@dataclass(frozen=True, eq=False)
class OrientationTarget:
    """Validated per-sample arrays: ``rotation`` ``(N, 3, 3)``; ``angular_velocity`` and
    ``angular_acceleration`` ``(N, 3)``."""

    rotation: Array
    angular_velocity: Array
    angular_acceleration: Array


def _rotations(value: object, n: int) -> tuple[Array, bool]:
    try:
        rotation = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"pose must be rotation matrices (3, 3) or ({n}, 3, 3), got {value!r}") from None
    if rotation.shape not in ((3, 3), (n, 3, 3)):
        raise InputError(f"pose must have shape (3, 3) or ({n}, 3, 3) for a path of {n} samples, got {rotation.shape}")
    constant = rotation.ndim == 2
    stack = np.broadcast_to(rotation, (n, 3, 3)).copy()
    if not np.isfinite(stack).all():
        raise InputError("pose must hold finite rotation matrices")
    deviation = np.abs(stack.transpose(0, 2, 1) @ stack - np.eye(3)).max(axis=(1, 2))
    bad = np.flatnonzero((deviation > ORTHONORMAL_TOLERANCE) | (np.linalg.det(stack) <= 0))
    if bad.size:
        i = int(bad[0])
        raise InputError(
            f"pose[{i}] is not a rotation matrix: |R^T R - I| = {deviation[i]:.3g} (tolerance "
            f"{ORTHONORMAL_TOLERANCE:g}), det = {np.linalg.det(stack[i]):.6g}"
        )
    return stack, constant


def _rates(value: ArrayLike | None, n: int, name: str) -> Array | None:
    if value is None:
        return None
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be an array of numbers, got {value!r}") from None
    if array.shape not in ((3,), (n, 3)) or not np.isfinite(array).all():
        raise InputError(f"{name} must be finite with shape (3,) or ({n}, 3), got shape {array.shape}")
    return np.broadcast_to(array, (n, 3)).copy()


def orientation_target(pose: object, n: int, exact_rates: bool) -> OrientationTarget:
    """Validate a ``pose`` argument (rotation array or :class:`OrientationPath`) for a path of ``n`` samples."""
    spec = pose if isinstance(pose, OrientationPath) else OrientationPath(pose)  # type: ignore[arg-type]
    rotation, constant = _rotations(spec.rotation, n)
    velocity = _rates(spec.angular_velocity, n, "angular_velocity")
    acceleration = _rates(spec.angular_acceleration, n, "angular_acceleration")
    if velocity is None or acceleration is None:
        if exact_rates and not constant:
            raise InputError(
                "exact rates of a changing orientation need its angular velocity and acceleration: pass "
                "vgtarm.ik.OrientationPath(rotation, angular_velocity, angular_acceleration), or use "
                "rates='finite_difference'"
            )
        velocity = np.zeros((n, 3)) if velocity is None else velocity
        acceleration = np.zeros((n, 3)) if acceleration is None else acceleration
    return OrientationTarget(rotation, velocity, acceleration)


def angle_error(rotation: Array, target: Array) -> Array:
    """Angle ``(n,)`` (rad) between orientations ``rotation`` and ``target`` ``(n, 3, 3)``, accurate near zero."""
    relative = target.transpose(0, 2, 1) @ rotation
    skew = 0.5 * np.stack(
        [
            relative[:, 2, 1] - relative[:, 1, 2],
            relative[:, 0, 2] - relative[:, 2, 0],
            relative[:, 1, 0] - relative[:, 0, 1],
        ],
        axis=1,
    )
    cosine = 0.5 * (np.trace(relative, axis1=1, axis2=2) - 1.0)
    return np.asarray(np.arctan2(np.linalg.norm(skew, axis=1), cosine))
