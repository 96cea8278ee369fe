"""The accepted inputs of the model: real numbers, in generous physical ranges.

**Numbers.** Every array a public method of :class:`~vgtarm.model.robot.Robot` takes must hold
real numbers (:func:`real_array`): complex values are refused even when their imaginary part is
zero (``numpy`` would drop it silently), and so are booleans, ``None``, text and other objects;
the message names the argument, the element and the user's own value, never a converted one.

**Joint values.** The model's formulas are defined far beyond the joint limits, but values far
beyond them are never a real configuration: with legs of 1e20 m the tip lands 6 km away, with
1e300 m every product overflows to NaN, and a twist of 1e20 rad has lost every digit of its
angle. The public methods therefore refuse joint values outside

- lengths (joints in metres): ``[max(0, lower - w), upper + w]`` with
  ``w = SANE_WIDENING * (upper - lower)`` (``lower``, ``upper``: the joint limits);
- angles (joints in radians): ``[lower - t, upper + t]`` with ``t = SANE_TURNS`` full turns.

For the reference robot that is legs in ``[0, 1.76]`` m (limits 0.22..0.36 m; ``[0, 2.06]`` m for
the diagonals, limits 0.30..0.46 m) and a twist within about +-6286 rad. The twist gets turns
rather than spans because it is a revolute joint that can spin freely (a free motion of the
model winds it up by tens of radians; its angle keeps 1e-12 rad resolution at 6000 rad).
Everything a controller or a solver legitimately visits (limits overshot by millimetres, a run
stopped ``limit_tolerance`` outside) lies far inside.

**Rates, efforts and tip forces** (:func:`input_ranges`), bounds no machine comes near, so that
only mistakes (a value in the wrong unit, an uninitialised array) and overflowing numbers are
refused:

- joint rates ``qd``: at most :data:`SANE_SPEED` (a million) spans of the joint's limits per
  second: legs of the reference robot +-1.4e5 m/s (400 times the speed of sound), the twist
  +-6.3e6 rad/s (a million turns a second; the fastest rotors make a few thousand);
- joint accelerations ``qdd``: that rate reached from rest in :data:`SANE_RAMP` (1 us, the finest
  sample spacing a path or reference accepts), so +-1e12 spans per second squared;
- actuator efforts ``F`` and the tip force ``f_tip``: at most :data:`SANE_EFFORT` = 1e12 N (N m for
  a twist), a thousand times the largest press ever built (about 8e8 N).

Inside these, the products of the model stay far below overflow for a robot of plausible
parameters (the reference robot's dynamics with every input at its bound at once stay below 1e17);
a result that is still not finite (a configuration at the very edge of assembly, or parameters
near the validation's extremes) is refused by the method, naming the input that drove it.

**Model factors** (:func:`model_factor`): a factor scaling the plant's masses, inertias or
friction into a controller's model (``RobotParameters.scaled``, ``--model-mass``) is accepted
within :data:`MODEL_FACTOR_RANGE`, three orders of magnitude either way: far beyond any modelling
error (the paper's studies use +-10 %); beyond, the model is no model of the plant (and its masses
soon leave the validated range). ``vgtarm.simulation.checks`` holds a controller's model to the
same range of ratios of its totals to the plant's.
"""

from __future__ import annotations

import decimal
import math
import numbers
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError, refuse_masked, shown

if TYPE_CHECKING:
    from .parameters import RobotParameters
    from .stack.description import Stack

Array = NDArray[np.float64]

#: Width of the accepted band on each side of a length's limits, in multiples of its span.
SANE_WIDENING = 10.0
#: Width of the accepted band on each side of an angle's limits, in full turns.
SANE_TURNS = 1000.0
#: Fastest accepted joint rate, in spans of the joint's limits per second.
SANE_SPEED = 1e6
#: The accepted accelerations reach :data:`SANE_SPEED` from rest in this time (s): the finest sample
#: spacing of a path or joint reference (``vgtarm.paths.MIN_DT``).
SANE_RAMP = 1e-6
#: Largest accepted actuator effort (N, N m for a twist) and tip force component (N).
SANE_EFFORT = 1e12
#: Names of the tip force's components in messages.
FORCE_NAMES = ("x", "y", "z")
#: Why each input's range is what it is, appended to a refusal.
RANGE_REASONS = {
    "qd": f" ({SANE_SPEED:g} spans of its limits a second)",
    "qdd": f" (that rate reached from rest in {SANE_RAMP:g} s)",
    "F": " (far beyond any actuator)",
    "f_tip": " (far beyond any tool force)",
}

#: Arrays of at most this many elements are checked element by element without a screen.
_SMALL = 256
#: What each kind of array holds that is not a real number, for messages.
_NOT_REAL = {"c": "complex", "b": "a boolean", "U": "text", "S": "text", "M": "a date", "m": "a time span"}


def sane_range(parameters: RobotParameters | Stack) -> tuple[Array, Array]:
    """Lowest and highest accepted value of each joint, ``(n,)`` each (m, rad)."""
    lower, upper = parameters.lower, parameters.upper
    lengths = np.array([unit == "m" for unit in parameters.joint_units[: len(lower)]])
    width = np.where(lengths, SANE_WIDENING * (upper - lower), SANE_TURNS * 2.0 * np.pi)
    low = lower - width
    low[lengths] = np.maximum(low[lengths], 0.0)
    return low, upper + width


def input_ranges(parameters: RobotParameters | Stack) -> dict[str, tuple[Array, Array]]:
    """Lowest and highest accepted value of each input of the model, by argument name.

    ``q``, ``qd``, ``qdd`` and ``F`` ``(n,)`` each (SI units of each joint: m, rad; per second;
    per second squared; N, N m) and ``f_tip`` ``(3,)`` (N). See the module's docstring.
    """
    span = np.asarray(parameters.upper - parameters.lower, dtype=float)
    speed = SANE_SPEED * span
    acceleration = speed / SANE_RAMP
    effort = np.full(span.shape, SANE_EFFORT)
    force = np.full(3, SANE_EFFORT)
    return {
        "q": sane_range(parameters),
        "qd": (-speed, speed),
        "qdd": (-acceleration, acceleration),
        "F": (-effort, effort),
        "f_tip": (-force, force),
    }


def input_units(parameters: RobotParameters | Stack) -> dict[str, tuple[str, ...]]:
    """The unit of each element of each input of :func:`input_ranges`, for messages."""
    units = tuple(parameters.joint_units)
    return {
        "q": units,
        "qd": tuple(f"{u}/s" for u in units),
        "qdd": tuple(f"{u}/s^2" for u in units),
        "F": tuple("N" if u == "m" else "N m" for u in units),
        "f_tip": ("N",) * 3,
    }


# -- real numbers ---------------------------------------------------------------------------------


def _element(name: str, index: tuple[int, ...], names: tuple[str, ...]) -> str:
    """``q[3, 6] (psi3)``: an element of argument ``name`` with the name of its last axis' entry."""
    label = f"{name}[{', '.join(map(str, index))}]"
    if index and len(names) > index[-1]:
        label += f" ({names[index[-1]]})"
    return label


def _what(x: object) -> str | None:
    """What a user's element is if it is not a real number (``None`` for a real number)."""
    if isinstance(x, bool | np.bool_):
        return "a boolean"
    if isinstance(x, numbers.Real | decimal.Decimal | np.floating | np.integer):
        return None
    if isinstance(x, complex | np.complexfloating):
        return "complex"
    if isinstance(x, str | bytes):
        return "text"
    return "not a number"


def real_array(value: Any, name: str, last: int, names: tuple[str, ...] = ()) -> NDArray[Any]:
    """``value`` as an array of real numbers of shape ``(..., last)``, not yet converted to float.

    Refuses, with one :class:`InputError` line naming ``name``: what is not an array of numbers
    (text, ragged lists), a masked array with masked entries (:func:`~vgtarm.errors.refuse_masked`),
    a wrong shape, and arrays holding complex values (even with a zero imaginary part), booleans,
    ``None``, text or other objects; the message names the first such element (with ``names[j]``
    for index ``j`` of the last axis) and shows the user's value.
    Integers, floats of any precision, ``Fraction`` and ``Decimal`` are real numbers. Nothing
    is copied for an array of floats (a broadcast view stays a view): convert with
    :func:`as_float` after checking the size of the work.
    """
    if isinstance(value, str | bytes):
        raise InputError(f"{name} must be an array of numbers, got {shown(value)}")
    refuse_masked(value, name)  # np.asarray would take the values under the mask
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError, OverflowError, RecursionError):
        raise InputError(f"{name} must be an array of numbers, got {shown(value)}") from None
    if raw.ndim == 0:
        raise InputError(f"{name} must be an array of shape (..., {last}), got {shown(value)}")
    if raw.shape[-1] != last:
        raise InputError(f"{name} must have shape (..., {last}), got shape {raw.shape}")
    kind = raw.dtype.kind
    if kind in "fiu":
        return raw
    if kind != "O" and not isinstance(value, np.ndarray):
        # NumPy turned the user's mixed list into one type ('0.28' and 0.28 both into text):
        # look at the user's own elements instead.
        try:
            objects = np.array(value, dtype=object)
        except (TypeError, ValueError):
            objects = raw
        raw = objects if objects.shape == raw.shape else raw
        kind = raw.dtype.kind
    if kind == "O":
        found = next(((i, x, w) for i, x in np.ndenumerate(raw) if (w := _what(x)) is not None), None)
        if found is None:
            return raw
        index, x, what = found
    else:
        what = _NOT_REAL.get(kind, "not a number")
        if raw.size == 0:
            raise InputError(f"{name} must be real numbers, got an empty array of {raw.dtype} ({what})")
        index = (0,) * raw.ndim
        if kind == "c":  # show an element whose imaginary part is not zero, if there is one
            imaginary = np.argwhere(raw.imag != 0)
            index = tuple(int(i) for i in imaginary[0]) if len(imaginary) else index
        x = raw[index]
    hint = f" (pass {name}.real if its real part is meant)" if what == "complex" else ""
    raise InputError(f"{name} must be real numbers; {_element(name, index, names)} = {_shown(x)} is {what}{hint}")


def _to_float(x: Any) -> float:
    try:
        return float(x)
    except OverflowError:  # an integer beyond any float
        return math.inf if x > 0 else -math.inf


def as_float(raw: NDArray[Any]) -> Array:
    """An array checked by :func:`real_array` as floats (a view if it already is one); an integer
    too large for a float becomes an infinity of its sign (refused by the range checks, which show
    the user's value)."""
    if raw.dtype == np.float64:
        return raw
    if raw.dtype.kind != "O":
        with np.errstate(over="ignore"):
            return np.asarray(raw, dtype=np.float64)
    return np.fromiter((_to_float(x) for x in raw.flat), dtype=np.float64, count=raw.size).reshape(raw.shape)


def user_finite(x: Any) -> bool:
    """Whether a user's element is a finite number in the user's eyes (a huge integer is)."""
    if isinstance(x, int):
        return True
    if isinstance(x, decimal.Decimal):
        return x.is_finite()
    try:
        return bool(np.isfinite(x))
    except (TypeError, OverflowError):
        return True


# -- ranges ---------------------------------------------------------------------------------------


def inside(array: Array, low: Array, high: Array) -> bool:
    """Whether every element of ``array`` ``(..., k)`` lies in ``[low, high]`` ``(k,)`` (NaN does not).

    A large array is first screened by its smallest and largest element, which allocates nothing
    (a broadcast view of a million rows stays free); only if that is not conclusive is it compared
    element by element."""
    if array.size <= _SMALL:
        if array.ndim == 1:  # one configuration: plain Python is fastest
            return all(lo <= x <= hi for x, lo, hi in zip(array.tolist(), low.tolist(), high.tolist(), strict=True))
        return bool(((array >= low) & (array <= high)).all())
    if array.min() >= low.max() and array.max() <= high.min():  # inside the narrowest range
        return True
    return bool(((array >= low) & (array <= high)).all())


def finite(array: NDArray[np.floating]) -> bool:
    """Whether every element of ``array`` is finite (fast for a small array).

    A large array is first summed, which allocates nothing: a NaN or an infinity makes the sum
    NaN or infinite, so a finite sum proves every element finite; only a sum that overflowed (or
    a value that is not finite) is looked at element by element."""
    if array.size <= _SMALL:
        return all(map(math.isfinite, array.ravel().tolist()))
    with np.errstate(over="ignore", invalid="ignore"):
        total = float(np.sum(array))
    if math.isfinite(total):
        return True
    return bool(np.isfinite(array).all())


def check_input(
    array: Array,
    name: str,
    bounds: tuple[Array, Array],
    names: tuple[str, ...],
    units: tuple[str, ...],
    *,
    raw: NDArray[Any] | None = None,
    explain: str | Callable[[int], str] = "",
) -> None:
    """Raise one :class:`InputError` line if an element of ``array`` ``(..., k)`` is not finite or lies
    outside ``bounds`` (``(k,)`` each).

    A non-finite value gives ``"qd must be finite; qd[2, 0] (s1) = nan"``; a finite one out of
    range ``"qd: s1 = 1e+308 m/s (configuration (2,)) is outside the accepted range [-1.4e+05,
    1.4e+05] m/s"`` and ``explain`` (text, or a function of the element's index on the last axis).
    The value shown is the user's (``raw``, before conversion)."""
    low, high = bounds
    if inside(array, low, high):
        return
    source = array if raw is None else raw
    for candidate in np.argwhere(~np.isfinite(array)):  # the user's NaN and infinities first
        index = tuple(int(i) for i in candidate)
        if not user_finite(source[index]):
            raise InputError(f"{name} must be finite; {_element(name, index, names)} = {_shown(source[index])}")
    index = tuple(int(i) for i in np.argwhere(~((array >= low) & (array <= high)))[0])
    j = index[-1]
    label = names[j] if j < len(names) else f"{name}[{j}]"
    unit = f" {units[j]}" if j < len(units) else ""
    location = f" (configuration {index[:-1]})" if len(index) > 1 else ""
    raise InputError(
        f"{name}: {label} = {_shown(source[index])}{unit}{location} is outside the accepted range "
        f"[{low[j]:.6g}, {high[j]:.6g}]{unit}{explain(j) if callable(explain) else explain}"
    )


def _shown(x: Any) -> str:
    """A user's element for a message: NumPy's scalars as the Python numbers they hold."""
    if isinstance(x, np.generic) and x.dtype != np.longdouble:
        x = x.item()
    return shown(x)


def check_joint_range(
    q: Array,
    parameters: RobotParameters | Stack,
    bounds: tuple[Array, Array],
    *,
    where: str = "q",
    raw: NDArray[Any] | None = None,
) -> None:
    """Raise :class:`InputError` if a joint value of ``q`` ``(..., n)`` lies outside ``bounds``
    (``sane_range(parameters)``, passed in so callers can keep it).

    The message names the first offending joint (paper name), its value (the user's, ``raw``, if
    given), the accepted range, the joint's limits and, for a batch, the configuration's index; a
    value that is not finite gives ``"q must be finite; q[6] (psi3) = nan"``.
    """
    if inside(q, *bounds):
        return
    lower, upper = parameters.lower, parameters.upper

    def limits(j: int) -> str:
        return f", far beyond its limits [{lower[j]:.6g}, {upper[j]:.6g}] (not a configuration of this robot)"

    names, units = tuple(parameters.joint_names), tuple(parameters.joint_units)
    check_input(q, where, bounds, names, units, raw=raw, explain=limits)


# -- model factors --------------------------------------------------------------------------------
