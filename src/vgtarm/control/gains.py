"""PD gain matrices of computed force control."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError, refuse_masked, shown
from ..model.parameters import N_JOINTS

Array = NDArray[np.float64]

#: Largest fixed position gain ``Kp`` (1/s^2) :func:`check_definite` accepts, on any joint: the
#: discretized error dynamics ``e'' + Kv e' + Kp e = 0`` stay stable only while ``Kp dt^2`` is
#: below about 4, which at the smallest control period vgtarm runs (1 us, ``vgtarm.paths.MIN_DT``)
#: is 4e12; a 1 kHz loop would need ``Kp`` under about 4e6 (the paper's are 5,000 to 20,000).
KP_MAX = 1e12
#: Largest fixed velocity gain ``Kv`` (1/s): ``Kv dt`` below 2, that is 2e6 at 1 us (2,000 at
#: 1 kHz; the paper's are 100 to 600), rounded down.
KV_MAX = 1e6
#: The largest fixed gain by its name (``Kp``, ``--kp``, ``Kv``, ``--kv``; the case aside).
_GAIN_MAX = {"kp": KP_MAX, "kv": KV_MAX}


def gain_matrix(value: ArrayLike, name: str, n: int = N_JOINTS) -> Array:
    """An n x n gain matrix (n joints, default the paper's 7) from a scalar (times the identity: the
    same gain on every joint), n diagonal entries or an n x n matrix."""
    expected = f"a number, {n} numbers or a {n}x{n} matrix"
    if isinstance(value, str | bytes) or value is None:
        raise InputError(f"{name} must be {expected}, got {shown(value)}")
    refuse_masked(value, name)
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{name} must be {expected}, got {shown(value)}") from None
    if array.shape not in ((), (n,), (n, n)):
        raise InputError(f"{name} must be {expected}, got shape {array.shape}")
    if not np.isfinite(array).all():  # before the scalar or the diagonal becomes a matrix (inf * 0)
        i = int(np.argwhere(~np.isfinite(array.reshape(-1)))[0][0])
        index = (i, i) if array.ndim < 2 else divmod(i, n)
        raise InputError(f"{name} must be finite, got {name}[{index[0]}, {index[1]}] = {float(array.flat[i])!r}")
    if array.ndim == 0:
        array = float(array) * np.eye(n)
    elif array.shape == (n,):
        array = np.diag(array)
    array = array.copy()
    array.flags.writeable = False
    return array


def check_definite(matrix: Array, name: str) -> None:
    """Refuse, in one :class:`InputError` line naming ``name``, fixed gains a controller cannot be
    run with: ``matrix`` (a gain matrix of :func:`gain_matrix`) must be symmetric and positive
    definite; for gains given per joint (a diagonal), each > 0. With these ``Kp`` and ``Kv`` the
    error dynamics of computed force control with an exact model, ``e'' + Kv e' + Kp e = 0``, are
    stable. A gain named ``Kp`` (``--kp``) or ``Kv`` (``--kv``) must also be at most
    :data:`KP_MAX` (1e12 1/s^2) or :data:`KV_MAX` (1e6 1/s) on every element: beyond, no control
    period vgtarm runs keeps the loop stable (``--kp 1e300`` diverges at once). The one check of
    ``vgtarm simulate --kp/--kv`` and of the exported controller (the library's
    :func:`vgtarm.simulation.simulate` runs any gains, unstable ones included)."""
    largest = _GAIN_MAX.get(name.lstrip("-").lower())
    if largest is not None and not (np.abs(matrix) <= largest).all():  # before eigvalsh meets 1e300
        i, j = (int(k) for k in np.argwhere(~(np.abs(matrix) <= largest))[0])
        raise InputError(
            f"{name} must be at most {largest:g} on every element (no control period vgtarm runs is stable"
            f" beyond), got {name}[{i}, {j}] = {float(matrix[i, j])!r}"
        )
    if not np.array_equal(matrix, matrix.T):
        i, j = (int(k) for k in np.argwhere(matrix != matrix.T)[0])
        raise InputError(
            f"{name} must be a symmetric matrix, got {name}[{i}, {j}] = {float(matrix[i, j])!r} and "
            f"{name}[{j}, {i}] = {float(matrix[j, i])!r}"
        )
    diagonal = np.diag(matrix)
    if not (diagonal > 0).all():
        i = int(np.argwhere(~(diagonal > 0))[0][0])
        raise InputError(
            f"{name} must be positive definite (each gain > 0), got {name}[{i}, {i}] = {float(diagonal[i])!r}"
        )
    smallest = float(np.linalg.eigvalsh(matrix)[0])
    if not smallest > 0:
        raise InputError(f"{name} must be positive definite, got a matrix whose smallest eigenvalue is {smallest:.6g}")


def gains_text(text: str, option: str, joint_names: tuple[str, ...]) -> float | tuple[float, ...]:
    """The gain of the command-line option ``option`` (``--kp``, ``--kv`` of ``vgtarm simulate`` and
    ``vgtarm export controller``): one number for every joint, or one per joint of ``joint_names``
    separated by commas, each finite and > 0 (:func:`check_definite` on the gains they make); else
    one :class:`InputError` line naming the option, the value and what was expected."""
    n = len(joint_names)
    largest = _GAIN_MAX.get(option.lstrip("-").lower())
    expected = (
        f"expected one number for every joint or {n} numbers separated by commas (one per joint: "
        f"{' '.join(joint_names)}), each finite and > 0" + ("" if largest is None else f" and at most {largest:g}")
    )
    if not text.isascii():  # float() reads other scripts' digits too: '١٠٠' (Arabic-Indic) as 100
        raise InputError(f"{option} {shown(text)}: {expected}, written in ASCII digits (0-9)")
    try:
        values = [float(cell) for cell in text.split(",")]
    except ValueError:
        raise InputError(f"{option} {shown(text)}: {expected}") from None
    if len(values) not in (1, n):
        raise InputError(f"{option} {shown(text)}: {expected}")
    value = values[0] if len(values) == 1 else tuple(values)
    try:
        check_definite(gain_matrix(value, option, n), option)
    except InputError:
        raise InputError(f"{option} {shown(text)}: {expected}") from None
    return value


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
