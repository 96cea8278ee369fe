"""Argument checks: what a number, a whole number, a probability, a seed, a flag, a choice and an
array of numbers are, and the one line that refuses one.

Every refusal reads ``name = value: expected what``: the field's name, the user's value as
:func:`vgtarm.errors.shown` renders it (a NumPy scalar as the Python number it holds) and what was
expected, with its unit in parentheses: ``dt = 0.0: expected a finite number > 0 (s)``. It is an
:class:`~vgtarm.errors.InputError` unless the caller passes another class as ``error`` (the
:class:`~vgtarm.errors.PathError` of a path, the :class:`~vgtarm.errors.ConfigError` of a file,
argparse's ``ArgumentTypeError``). An empty ``name`` leaves the naming to the caller: an argparse
type, which argparse prefixes with ``argument --option:``, reads ``expected what, got value``.

**Numbers.** A number is a real number (:class:`numbers.Real`): a Python ``int`` or ``float``, a
``Fraction``, a NumPy integer or floating scalar. Booleans (Python's and NumPy's) are not numbers,
and neither are text (nothing is read from text here), complex numbers, ``Decimal`` (which does
not mix with floats), arrays (a 0-d one included), ``None`` or other objects. A number a check
accepts is also finite: NaN, the infinities and an integer too large for a float are refused. A
whole number is an integer of those kinds (:class:`numbers.Integral`; ``5.0`` is not one).

**Bounds.** ``minimum`` and ``maximum`` are inclusive, ``above`` and ``below`` exclusive; give at
most one of each pair. Checks that are not about one value alone (a bound set by another
argument, a relation between two fields) refuse with :func:`refuse`, in the same form.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Collection, Hashable
from typing import Any, NoReturn, TypeVar, cast

import numpy as np
from numpy.typing import NDArray

from .errors import InputError, VgtarmError, refuse_masked, shown

__all__ = [
    "MAX_SEED",
    "choice",
    "finite_array",
    "flag",
    "interval",
    "is_number",
    "number",
    "number_array",
    "positive",
    "probability",
    "refuse",
    "seed",
    "vector",
    "whole",
]

#: Largest seed accepted wherever a seed enters vgtarm (the GA's ``seed``, a run's ``seed`` in
#: :func:`vgtarm.simulation.simulate`, a study's ``seeds`` and ``random.seed``, the command line's
#: ``--seed``): seeds are whole numbers from 0 to 2**63 - 1. NumPy's generators take any whole
#: number >= 0, but a run's seed is stored as a 64-bit signed integer (a study's results table), so
#: a larger one would run and fail only when stored.
MAX_SEED = 2**63 - 1
#: What a seed is, in a refusal.
SEED_RANGE = f"a whole number from 0 to 2**63 - 1 = {MAX_SEED}"

Error = type[Exception]
T = TypeVar("T")


# -- the message --------------------------------------------------------------------------------------


def _plain(value: object) -> object:
    """A NumPy scalar as the Python value it holds (for the message), else ``value``."""
    if isinstance(value, np.generic) and not isinstance(value, np.longdouble):
        return value.item()
    return value


def refuse(name: str, value: object, expected: str, error: Error = InputError) -> NoReturn:
    """Raise ``error("name = value: expected what")``, the one refusal of this module.

    ``value`` is shown with :func:`vgtarm.errors.shown` (cut to a line); an empty ``name`` gives
    ``"expected what, got value"`` for a caller that names the field itself (argparse)."""
    text = shown(_plain(value))
    raise error(f"{name} = {text}: expected {expected}" if name else f"expected {expected}, got {text}")


def _bound(x: float) -> str:
    """A bound in a message: a whole number with thousands separators, else ``:g``."""
    return f"{int(x):,}" if isinstance(x, numbers.Integral) else f"{float(x):g}"


def _unit(unit: str) -> str:
    return f" ({unit})" if unit else ""


def _limits(
    minimum: float | None, maximum: float | None, above: float | None, below: float | None
) -> tuple[tuple[float, bool] | None, tuple[float, bool] | None]:
    """The lower and upper bound as ``(value, inclusive)``, or None."""
    if minimum is not None and above is not None:
        raise TypeError("give minimum or above, not both")
    if maximum is not None and below is not None:
        raise TypeError("give maximum or below, not both")
    low = (minimum, True) if minimum is not None else (above, False) if above is not None else None
    high = (maximum, True) if maximum is not None else (below, False) if below is not None else None
    return low, high


def _range(
    kind: str,
    low: tuple[float, bool] | None,
    high: tuple[float, bool] | None,
    unit: str,
    *,
    finite: bool = True,
) -> str:
    """``a finite number >= 0 (N)``, ``a number in [0, 1) (m)``, ``a whole number from 1 to 32``:
    ``kind`` with its bounds; "finite" is said where a side is open (a number in [0, 1] is finite)."""
    if low is not None and high is not None:
        if kind.startswith("a whole") and low[1] and high[1]:
            text = f"{kind} from {_bound(low[0])} to {_bound(high[0])}"
        else:
            text = f"{kind} in {'[' if low[1] else '('}{_bound(low[0])}, {_bound(high[0])}{']' if high[1] else ')'}"
    else:
        head, _, last = kind.rpartition(" ")
        text = f"{head} finite {last}" if finite else kind
        if low is not None:
            text += f" {'>=' if low[1] else '>'} {_bound(low[0])}"
        if high is not None:
            text += f" {'<=' if high[1] else '<'} {_bound(high[0])}"
    return text + _unit(unit)


def _inside(x: float, low: tuple[float, bool] | None, high: tuple[float, bool] | None) -> bool:
    if low is not None and not (x >= low[0] if low[1] else x > low[0]):
        return False
    return high is None or (x <= high[0] if high[1] else x < high[0])


# -- numbers ------------------------------------------------------------------------------------------


def is_number(value: object) -> bool:
    """Whether ``value`` is a real number (see the module's docstring; it may not be finite)."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)


def _float(x: Any) -> float:
    """A real number as a float; an integer beyond any float as the infinity of its sign."""
    try:
        return float(x)
    except OverflowError:
        return math.inf if x > 0 else -math.inf


def _finite_float(value: object) -> float | None:
    """``value`` as a finite float, or None if it is not a finite real number."""
    if not is_number(value):
        return None
    x = _float(value)  # an integer beyond any float is an infinity, refused as one
    return x if math.isfinite(x) else None


def number(
    name: str,
    value: object,
    *,
    minimum: float | None = None,
    maximum: float | None = None,
    above: float | None = None,
    below: float | None = None,
    unit: str = "",
    expected: str | None = None,
    error: Error = InputError,
) -> float:
    """``value`` as a float: a finite real number within the bounds given, else one ``error`` line
    ``name = value: expected a number in [minimum, maximum] (unit)`` (or ``expected`` instead of
    the generated description)."""
    low, high = _limits(minimum, maximum, above, below)
    x = _finite_float(value)
    if x is None or not _inside(x, low, high):
        refuse(name, value, expected or _range("a number", low, high, unit), error)
    return x


def positive(
    name: str,
    value: object,
    unit: str = "",
    *,
    maximum: float | None = None,
    expected: str | None = None,
    error: Error = InputError,
) -> float:
    """``value`` as a finite float > 0 (and at most ``maximum``), as :func:`number`."""
    return number(name, value, above=0, maximum=maximum, unit=unit, expected=expected, error=error)


def probability(name: str, value: object, *, error: Error = InputError) -> float:
    """``value`` as a float in ``[0, 1]``, as :func:`number`."""
    return number(name, value, minimum=0, maximum=1, expected="a probability in [0, 1]", error=error)


def whole(
    name: str,
    value: object,
    minimum: int | None = None,
    maximum: int | None = None,
    *,
    unit: str = "",
    expected: str | None = None,
    error: Error = InputError,
) -> int:
    """``value`` as an int: a whole number from ``minimum`` to ``maximum`` (both inclusive, either
    may be None), else one ``error`` line ``name = value: expected a whole number from 1 to 32``."""
    low = None if minimum is None else (minimum, True)
    high = None if maximum is None else (maximum, True)
    if not (isinstance(value, numbers.Integral) and not isinstance(value, bool) and _inside(int(value), low, high)):
        refuse(name, value, expected or _range("a whole number", low, high, unit, finite=False), error)
    return int(value)


def seed(name: str, value: object, *, expected: str | None = None, error: Error = InputError) -> int:
    """``value`` as a seed: a whole number from 0 to :data:`MAX_SEED`, as :func:`whole`."""
    return whole(name, value, 0, MAX_SEED, expected=expected or SEED_RANGE, error=error)


def flag(name: str, value: object, *, error: Error = InputError) -> bool:
    """``value`` as a bool: ``True`` or ``False`` (NumPy's too; ``0`` and ``1`` are not flags)."""
    if not isinstance(value, bool | np.bool_):
        refuse(name, value, "True or False", error)
    return bool(value)


def choice(name: str, value: T, choices: Collection[T], *, error: Error = InputError) -> T:
    """``value`` itself if it is one of ``choices``, else one ``error`` line listing them."""
    if not (isinstance(value, Hashable) and value in choices):
        refuse(name, value, f"one of {list(choices)}", error)
    return value


def vector(
    name: str,
    value: object,
    n: int,
    *,
    minimum: float | None = None,
    maximum: float | None = None,
    above: float | None = None,
    below: float | None = None,
    unit: str = "",
    expected: str | None = None,
    error: Error = InputError,
) -> tuple[float, ...]:
    """``value`` (a tuple or a list) as ``n`` finite floats within the bounds given, else one
    ``error`` line showing the whole value: ``name = [0, nan, 1]: expected 3 numbers in [-10, 10]
    (m)``. For the few numbers that make one field of a record (a point, a pair); arrays of data are
    :func:`finite_array`'s, which names the element."""
    low, high = _limits(minimum, maximum, above, below)
    if isinstance(value, tuple | list) and len(value) == n:
        floats = [_finite_float(x) for x in value]
        if all(x is not None and _inside(x, low, high) for x in floats):
            return tuple(cast(list[float], floats))
    kind = "a number" if n == 1 else f"{n} numbers"
    refuse(name, value, expected or _range(kind, low, high, unit), error)


def interval(
    name: str,
    value: object,
    *,
    minimum: float | None = None,
    maximum: float | None = None,
    above: float | None = None,
    below: float | None = None,
    unit: str = "",
    expected: str | None = None,
    error: Error = InputError,
) -> tuple[float, float]:
    """``value`` as a pair ``(low, high)`` of finite floats with ``low < high``, both within the
    bounds given, else one ``error`` line: ``name = (2, 1): expected [min, max] with min < max``."""
    low, high = _limits(minimum, maximum, above, below)
    bounds = "" if low is None and high is None else ", " + _range("each", low, high, "", finite=False)
    text = expected or f"[min, max] with min < max{bounds}{_unit(unit)}"
    pair = vector(
        name, value, 2, minimum=minimum, maximum=maximum, above=above, below=below, expected=text, error=error
    )
    if not pair[0] < pair[1]:
        refuse(name, value, text, error)
    return pair[0], pair[1]


# -- arrays -------------------------------------------------------------------------------------------


def _shape(shape: tuple[int | None, ...]) -> str:
    """``(n, 3)``: a shape with its free lengths named."""
    free = iter("nmk")
    parts = [str(d) if d is not None else next(free, "n") for d in shape]
    return f"({parts[0]},)" if len(parts) == 1 else f"({', '.join(parts)})"


def number_array(
    name: str, value: object, shape: tuple[int | None, ...] | None = None, *, error: Error = InputError
) -> NDArray[np.float64]:
    """``value`` as a float64 array (not copied if it is one), of ``shape`` if given (``None`` for a
    length that may be anything); its elements may be NaN or infinite (:func:`finite_array` refuses
    them).

    Refused, in one ``error`` line naming ``name``: text, ``None``, ragged lists, a masked array with
    masked entries (:func:`vgtarm.errors.refuse_masked`), arrays of booleans, complex numbers, text
    or other objects (``name = 'abc': expected an array of numbers``), and a wrong shape
    (``name.shape = (2, 2): expected (n, 3)``). A list is converted as NumPy converts it: a boolean
    among floats becomes 0.0 or 1.0 (the array's type is what is checked)."""
    if isinstance(value, str | bytes) or value is None:
        refuse(name, value, "an array of numbers", error)
    refuse_masked(value, name, cast(type[VgtarmError], error))
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError, OverflowError, RecursionError):  # ragged nested lists
        refuse(name, value, "an array of numbers", error)
    kind = raw.dtype.kind
    if kind == "O" and all(is_number(x) for x in raw.flat):  # Fractions, integers beyond 64 bits
        raw = np.array([_float(x) for x in raw.flat], dtype=np.float64).reshape(raw.shape)
    elif kind not in "iuf":
        refuse(name, value, "an array of numbers", error)
    if shape is not None and (
        raw.ndim != len(shape) or any(d is not None and d != k for d, k in zip(shape, raw.shape, strict=True))
    ):
        refuse(f"{name}.shape" if name else "", raw.shape, _shape(shape), error)
    return raw.astype(np.float64, copy=False)


def finite_array(
    name: str, value: object, shape: tuple[int | None, ...] | None = None, *, error: Error = InputError
) -> NDArray[np.float64]:
    """``value`` as a float64 array of finite numbers, as :func:`number_array`; the first element
    that is NaN or infinite (an integer beyond any float counts as an infinity) is refused by its
    index: ``position[4, 1] = nan: expected a finite number``."""
    array = number_array(name, value, shape, error=error)
    if not np.isfinite(array).all():
        index = tuple(int(i) for i in np.argwhere(~np.isfinite(array))[0])
        where = f"{name}[{', '.join(map(str, index))}]" if index and name else name
        refuse(where, float(array[index]), "a finite number", error)
    return array


def comma_numbers(name: str, text: str, count: int, meaning: str, *, error: Error = InputError) -> NDArray[np.float64]:
    """``count`` comma-separated finite numbers written in ``text`` (``"0,0.26,0.97"``), or one ``error``
    line naming ``name``, showing the text and saying what it means."""
    cells = text.split(",") if isinstance(text, str) else []
    try:
        values = np.array([float(cell) for cell in cells], dtype=np.float64)
    except ValueError:
        values = np.array([np.nan])
    if values.shape != (count,) or not np.isfinite(values).all():
        raise error(f"{name} {shown(text)}: expected {count} finite numbers separated by commas ({meaning})")
    return values
