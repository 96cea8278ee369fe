"""PD gain matrices of computed force control."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError

Array = NDArray[np.float64]


def gain_matrix(value: ArrayLike, name: str) -> Array:
    """A 7x7 gain matrix from a scalar (times the identity), 7 diagonal entries or a 7x7 matrix."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, 7 numbers or a 7x7 matrix, got {value!r}") from None
    if array.ndim == 0:
        array = float(array) * np.eye(7)
    elif array.shape == (7,):
        array = np.diag(array)
    elif array.shape != (7, 7):
        raise InputError(f"{name} must be a number, 7 numbers or a 7x7 matrix, got shape {array.shape}")
    if not np.isfinite(array).all():
        raise InputError(f"{name} must be finite, got {array.tolist()}")
    array = array.copy()
    array.flags.writeable = False
    return array


@dataclass(frozen=True, eq=False)
class Gains:
    """Position and velocity gains ``Kp``, ``Kv`` (7x7, 1/s^2 and 1/s) of eq. 19."""

    Kp: Array
    Kv: Array

    @classmethod
    def of(cls, Kp: ArrayLike, Kv: ArrayLike) -> Gains:
        """Gains from scalars, diagonals or full matrices."""
        return cls(gain_matrix(Kp, "Kp"), gain_matrix(Kv, "Kv"))
