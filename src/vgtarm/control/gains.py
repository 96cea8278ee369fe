"""PD gain matrices of computed force control."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError, shown
from ..model.parameters import N_JOINTS

Array = NDArray[np.float64]


def gain_matrix(value: ArrayLike, name: str, n: int = N_JOINTS) -> Array:
    """An n x n gain matrix (n joints, default the paper's 7) from a scalar (times the identity: the
    same gain on every joint), n diagonal entries or an n x n matrix."""
    expected = f"a number, {n} numbers or a {n}x{n} matrix"
    if isinstance(value, str | bytes) or value is None:
        raise InputError(f"{name} must be {expected}, got {shown(value)}")
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{name} must be {expected}, got {shown(value)}") from None
    if array.ndim == 0:
        array = float(array) * np.eye(n)
    elif array.shape == (n,):
        array = np.diag(array)
    elif array.shape != (n, n):
        raise InputError(f"{name} must be {expected}, got shape {array.shape}")
    if not np.isfinite(array).all():
        i, j = (int(k) for k in np.argwhere(~np.isfinite(array))[0])
        raise InputError(f"{name} must be finite, got {name}[{i}, {j}] = {float(array[i, j])!r}")
    array = array.copy()
    array.flags.writeable = False
    return array


@dataclass(frozen=True, eq=False)
class Gains:
    """Position and velocity gains ``Kp``, ``Kv`` (n x n, 1/s^2 and 1/s) of eq. 19."""

    Kp: Array
    Kv: Array

    @classmethod
    def of(cls, Kp: ArrayLike, Kv: ArrayLike, n: int = N_JOINTS) -> Gains:
        """Gains of a robot with ``n`` joints (default the paper's 7) from scalars, diagonals or full
        matrices."""
        return cls(gain_matrix(Kp, "Kp", n), gain_matrix(Kv, "Kv", n))

    @property
    def n(self) -> int:
        """Number of joints the gains are for."""
        return int(self.Kp.shape[0])


def real_number(name: str, value: object, expected: str, *, minimum: float = 0.0, strict: bool = True) -> float:
    """``value`` as a finite float ``> minimum`` (``>=`` unless ``strict``), else one
    :class:`InputError` line naming ``name`` and what was ``expected``. Strings, ``None`` and
    booleans are refused, not converted."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise InputError(f"{name} = {shown(value)}: expected {expected}")
    try:
        number = float(value)
    except OverflowError:  # an int beyond any float
        raise InputError(f"{name} = {shown(value)}: expected {expected}") from None
    if not (np.isfinite(number) and (number > minimum if strict else number >= minimum)):
        raise InputError(f"{name} = {shown(value)}: expected {expected}")
    return number


def check_within(gains: Gains, kp_bounds: tuple[float, float], kv_bounds: tuple[float, float]) -> None:
    """Raise :class:`InputError` naming the first element of ``gains`` outside its bounds."""
    for label, matrix, (lo, hi) in (("Kp", gains.Kp, kp_bounds), ("Kv", gains.Kv, kv_bounds)):
        outside = np.argwhere((matrix < lo) | (matrix > hi))
        if outside.size:
            i, j = (int(k) for k in outside[0])
            raise InputError(
                f"fixed gains {label}[{i}, {j}] = {float(matrix[i, j]):g} is outside {label.lower()}_bounds = "
                f"[{lo:g}, {hi:g}] (every element of the GA's gains lies within the bounds)"
            )
