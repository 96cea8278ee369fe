"""The argument checks of :mod:`vgtarm.checks`: what each accepts, and the one line that refuses."""

from __future__ import annotations

import argparse
import math
import re
from fractions import Fraction
from typing import Any

import numpy as np
import pytest

from vgtarm import checks
from vgtarm.errors import ConfigError, InputError, PathError

#: Numbers of every kind a check accepts: Python's, a Fraction, NumPy's scalars of each width.
NUMBERS = [2, 2.0, Fraction(2), np.int8(2), np.int64(2), np.uint16(2), np.float16(2.0), np.float32(2.0), np.float64(2)]
#: What is not a number: booleans (Python's and NumPy's), text, None, complex, arrays, Decimal.
NOT_NUMBERS = [True, False, np.bool_(True), "2", b"2", None, 2 + 0j, [2.0], np.array(2.0), np.array([2.0])]
NOT_FINITE = [math.nan, math.inf, -math.inf, np.float64("nan"), np.float32("inf"), 10**400]


def refused(call: Any, message: str, error: type[Exception] = InputError) -> None:
    """``call()`` raises ``error`` whose whole message is ``message``, on one line."""
    with pytest.raises(error, match="^" + re.escape(message) + "$"):
        call()


# -- numbers --------------------------------------------------------------------------------------


@pytest.mark.parametrize("value", NUMBERS, ids=lambda v: type(v).__name__)
def test_numbers_of_every_kind_are_accepted_as_python_floats(value: Any) -> None:
    assert checks.is_number(value)
    x = checks.number("x", value)
    assert x == 2.0 and type(x) is float
    assert type(checks.positive("x", value)) is float
    assert checks.number("x", value, minimum=2, maximum=2) == 2.0  # both bounds inclusive


@pytest.mark.parametrize("value", NOT_NUMBERS, ids=repr)
def test_booleans_text_none_complex_and_arrays_are_not_numbers(value: Any) -> None:
    assert not checks.is_number(value)
    with pytest.raises(InputError, match=r"^x = .*: expected a finite number$"):
        checks.number("x", value)
    with pytest.raises(InputError, match=r"^x = .*: expected a whole number$"):
        checks.whole("x", value)


@pytest.mark.parametrize("value", NOT_FINITE, ids=repr)
def test_nan_infinities_and_integers_beyond_a_float_are_refused(value: Any) -> None:
    assert checks.is_number(value)  # real numbers, but no finite one
    with pytest.raises(InputError, match=r"^x = .*: expected a finite number >= 0 \(m\)$"):
        checks.number("x", value, minimum=0, unit="m")
    with pytest.raises(InputError, match=r"^x = .*: expected a number in \(0, 1\]$"):
        checks.number("x", value, above=0, maximum=1)


def test_a_number_message_names_the_field_shows_the_value_and_says_what_was_expected() -> None:
    refused(lambda: checks.number("dt", 0.0, above=0, unit="s"), "dt = 0.0: expected a finite number > 0 (s)")
    refused(lambda: checks.number("dt", np.float32(-1.5), minimum=0), "dt = -1.5: expected a finite number >= 0")
    refused(lambda: checks.number("f", 5, maximum=2, unit="N"), "f = 5: expected a finite number <= 2 (N)")
    refused(lambda: checks.number("f", 5, below=2), "f = 5: expected a finite number < 2")
    refused(lambda: checks.number("p", 1, minimum=0, below=1), "p = 1: expected a number in [0, 1)")
    refused(lambda: checks.number("p", 0.0, above=0, below=1), "p = 0.0: expected a number in (0, 1)")
    refused(
        lambda: checks.number("big", 2e6, maximum=1_000_000), "big = 2000000.0: expected a finite number <= 1,000,000"
    )
    refused(lambda: checks.number("g", "9.81"), "g = '9.81': expected a finite number")
    refused(lambda: checks.number("g", True, expected="a gravity (m/s^2)"), "g = True: expected a gravity (m/s^2)")


@pytest.mark.parametrize(
    ("bounds", "inside", "outside"),
    [
        ({"minimum": 1.0}, [1.0, 2.0], [0.999]),
        ({"above": 1.0}, [1.000001, 2.0], [1.0, 0.0]),
        ({"maximum": 1.0}, [1.0, -5.0], [1.000001]),
        ({"below": 1.0}, [0.999999, -5.0], [1.0]),
        ({"minimum": 0, "maximum": 1}, [0, 0.5, 1], [-1e-300, 1.0000001]),
        ({"above": 0, "below": 1}, [1e-300, 0.5], [0, 1]),
    ],
)
def test_minimum_and_maximum_are_inclusive_above_and_below_exclusive(
    bounds: dict[str, float], inside: list[float], outside: list[float]
) -> None:
    for value in inside:
        assert checks.number("x", value, **bounds) == value
    for value in outside:
        with pytest.raises(InputError, match=r"^x = "):
            checks.number("x", value, **bounds)


def test_a_bound_is_given_once() -> None:
    with pytest.raises(TypeError):
        checks.number("x", 1.0, minimum=0, above=0)
    with pytest.raises(TypeError):
        checks.number("x", 1.0, maximum=2, below=2)


def test_positive_and_probability() -> None:
    assert checks.positive("dt", np.float64(1e-300), "s") == 1e-300
    refused(lambda: checks.positive("dt", 0, "s"), "dt = 0: expected a finite number > 0 (s)")
    refused(lambda: checks.positive("dt", 2, "s", maximum=1), "dt = 2: expected a number in (0, 1] (s)")
    assert checks.probability("p", 0) == 0.0 and checks.probability("p", np.float32(1.0)) == 1.0
    for value in (-0.001, 1.001, math.nan, True, "0.5"):
        with pytest.raises(InputError, match=r"^p = .*: expected a probability in \[0, 1\]$"):
            checks.probability("p", value)


# -- whole numbers, seeds, flags, choices ---------------------------------------------------------


@pytest.mark.parametrize("value", [3, np.int8(3), np.int64(3), np.uint64(3), 2**70 // 2**69 + 1])
def test_whole_numbers_of_every_integer_kind_are_accepted_as_ints(value: Any) -> None:
    n = checks.whole("n", value, 1, 3)
    assert n == 3 and type(n) is int


@pytest.mark.parametrize("value", [3.0, np.float64(3.0), Fraction(3), True, np.bool_(True), "3", None])
def test_what_is_not_an_integer_is_not_a_whole_number(value: Any) -> None:
    with pytest.raises(InputError, match=r"^n = .*: expected a whole number from 1 to 3$"):
        checks.whole("n", value, 1, 3)


def test_a_whole_number_message_and_bounds() -> None:
    assert checks.whole("n", 10**30, 0) == 10**30  # no float in between: any integer
    refused(lambda: checks.whole("n", 0, 1), "n = 0: expected a whole number >= 1")
    refused(lambda: checks.whole("n", 33, 1, 32), "n = 33: expected a whole number from 1 to 32")
    refused(lambda: checks.whole("n", 11, maximum=10), "n = 11: expected a whole number <= 10")
    refused(
        lambda: checks.whole("substeps", 2_000_000, 1, 1_000_000, unit="steps"),
        "substeps = 2000000: expected a whole number from 1 to 1,000,000 (steps)",
    )


def test_seeds_are_whole_numbers_from_0_to_2_to_the_63_minus_1() -> None:
    assert checks.seed("seed", 0) == 0 and checks.seed("seed", np.uint64(checks.MAX_SEED)) == 2**63 - 1
    expected = "expected a whole number from 0 to 2**63 - 1 = 9223372036854775807"
    for value in (-1, 2**63, True, 1.0, "1"):
        with pytest.raises(ConfigError, match="^random.seed = .*: " + re.escape(expected) + "$"):
            checks.seed("random.seed", value, error=ConfigError)


def test_flags_are_python_or_numpy_booleans() -> None:
    assert checks.flag("fallback", True) is True and checks.flag("fallback", np.bool_(False)) is False
    for value in (0, 1, "yes", None, np.array([True])):
        with pytest.raises(InputError, match=r"^fallback = .*: expected True or False$"):
            checks.flag("fallback", value)


def test_a_choice_is_one_of_the_choices_and_the_refusal_lists_them() -> None:
    assert checks.choice("blend", "cubic", ("cubic", "quintic")) == "cubic"
    assert checks.choice("switch_on", None, ("measured", None)) is None
    assert checks.choice("prediction", "linear", {"linear": 0, "quadratic": 1}) == "linear"  # a mapping's keys
    refused(
        lambda: checks.choice("blend", "linear", ("cubic", "quintic")),
        "blend = 'linear': expected one of ['cubic', 'quintic']",
    )
    for value in ([], np.array(["cubic"]), 1, b"cubic"):  # unhashable, an array, another type
        with pytest.raises(InputError, match=r"^blend = .*: expected one of \['cubic'\]$"):
            checks.choice("blend", value, ("cubic",))


# -- a few numbers of one field -------------------------------------------------------------------


def test_a_vector_is_a_tuple_or_list_of_n_finite_numbers_within_the_bounds() -> None:
    assert checks.vector("tool", [0, np.float32(0.5), Fraction(1, 4)], 3) == (0.0, 0.5, 0.25)
    assert checks.vector("eta", (5.0, 5.0, 5.0), 3, minimum=0, unit="N") == (5.0, 5.0, 5.0)
    refused(
        lambda: checks.vector("eta", (5.0, -1.0, 5.0), 3, minimum=0, unit="N"),
        "eta = (5.0, -1.0, 5.0): expected 3 finite numbers >= 0 (N)",
    )
    refused(
        lambda: checks.vector("tool", [0, math.nan, 0], 3, minimum=-1, maximum=1, unit="m"),
        "tool = [0, nan, 0]: expected 3 numbers in [-1, 1] (m)",
    )
    for value in ((0.0, 1.0), (0.0, 1.0, 2.0, 3.0), np.zeros(3), "abc", (0.0, True, 1.0), None):
        with pytest.raises(InputError, match=r"^v = .*: expected 3 finite numbers$"):
            checks.vector("v", value, 3)
    refused(
        lambda: checks.vector("v", [1.0, 2.0], 3, expected="a point [x, y, z]"),
        "v = [1.0, 2.0]: expected a point [x, y, z]",
    )


def test_an_interval_is_a_pair_with_min_below_max() -> None:
    assert checks.interval("kp_bounds", (0, 5000)) == (0.0, 5000.0)
    refused(
        lambda: checks.interval("kp_bounds", (1.0, 1.0)), "kp_bounds = (1.0, 1.0): expected [min, max] with min < max"
    )
    refused(lambda: checks.interval("kp_bounds", "ab"), "kp_bounds = 'ab': expected [min, max] with min < max")
    refused(
        lambda: checks.interval("limits", [0.0, 0.3], above=0, maximum=10, unit="m", error=ConfigError),
        "limits = [0.0, 0.3]: expected [min, max] with min < max, each in (0, 10] (m)",
        ConfigError,
    )
    refused(
        lambda: checks.interval("limits", [-1, math.inf], minimum=-1),
        "limits = [-1, inf]: expected [min, max] with min < max, each >= -1",
    )


# -- arrays ---------------------------------------------------------------------------------------


def test_a_number_array_is_a_float64_array_of_the_shape_given() -> None:
    same = np.zeros((4, 3))
    assert checks.number_array("p", same, (None, 3)) is same  # not copied
    converted = checks.number_array("p", [[1, 2, 3]], (None, 3))
    assert converted.dtype == np.float64 and converted.shape == (1, 3)
    assert checks.number_array("p", [Fraction(1, 2), 10**400]).tolist() == [0.5, math.inf]  # objects: each a number
    assert np.isnan(checks.number_array("costs", [math.nan, 1.0])[0])  # NaN and infinities are numbers here
    refused(lambda: checks.number_array("p", np.zeros((2, 2)), (None, 3)), "p.shape = (2, 2): expected (n, 3)")
    refused(lambda: checks.number_array("p", np.zeros(2), (3,)), "p.shape = (2,): expected (3,)")
    refused(lambda: checks.number_array("p", np.zeros((2, 3, 1)), (None, None)), "p.shape = (2, 3, 1): expected (n, m)")


@pytest.mark.parametrize(
    "value",
    ["abc", None, [[1.0], [1.0, 2.0]], [True, False], [1 + 2j], ["1.0"], [None, 1.0], [{"a": 1}]],
    ids=["text", "None", "ragged", "booleans", "complex", "text in a list", "None in a list", "objects"],
)
def test_what_is_not_an_array_of_numbers_is_refused_showing_it(value: Any) -> None:
    with pytest.raises(PathError, match=r"^position = .*: expected an array of numbers$"):
        checks.number_array("position", value, error=PathError)


def test_a_masked_array_with_masked_entries_is_refused() -> None:
    with pytest.raises(InputError, match=r"^q is a masked array with 1 masked entry \(at \[1\]\)"):
        checks.finite_array("q", np.ma.array([1.0, 2.0], mask=[False, True]))
    assert checks.finite_array("q", np.ma.array([1.0, 2.0])).tolist() == [1.0, 2.0]


def test_a_finite_array_names_its_first_element_that_is_not_finite() -> None:
    assert checks.finite_array("t", np.arange(3, dtype=np.float32), (3,)).dtype == np.float64
    refused(lambda: checks.finite_array("t", [0.0, math.nan, math.inf]), "t[1] = nan: expected a finite number")
    refused(
        lambda: checks.finite_array("position", [[0, 0, 0], [0, 0, -math.inf]], (None, 3), error=PathError),
        "position[1, 2] = -inf: expected a finite number",
        PathError,
    )
    refused(lambda: checks.finite_array("x", np.float64(math.nan)), "x = nan: expected a finite number")


# -- the one form ---------------------------------------------------------------------------------


def test_refuse_is_the_one_form_and_an_empty_name_is_argparses() -> None:
    refused(
        lambda: checks.refuse("gain", np.float64(3.5), "at most 1/dt = 2 1/s"),
        "gain = 3.5: expected at most 1/dt = 2 1/s",
    )
    with pytest.raises(InputError, match=r"^text = '\\x1b\[2Jx+\.\.\. \(\d+ more characters\): expected a name$"):
        checks.refuse("text", "\x1b[2J" + "x" * 100, "a name")  # escaped and cut, as errors.shown does
    refused(
        lambda: checks.whole("", 0, 1, error=argparse.ArgumentTypeError),
        "expected a whole number >= 1, got 0",
        argparse.ArgumentTypeError,
    )
    refused(lambda: checks.number_array("", np.zeros(2), (3,)), "expected (3,), got (2,)")


@pytest.mark.parametrize("error", [InputError, PathError, ConfigError, ValueError])
def test_every_check_raises_the_class_it_is_given(error: type[Exception]) -> None:
    calls = [
        lambda: checks.number("x", "1", error=error),
        lambda: checks.positive("x", 0, error=error),
        lambda: checks.probability("x", 2, error=error),
        lambda: checks.whole("x", 1.5, error=error),
        lambda: checks.seed("x", -1, error=error),
        lambda: checks.flag("x", 1, error=error),
        lambda: checks.choice("x", "c", ("a", "b"), error=error),
        lambda: checks.vector("x", (1.0,), 2, error=error),
        lambda: checks.interval("x", (2.0, 1.0), error=error),
        lambda: checks.number_array("x", "a", error=error),
        lambda: checks.finite_array("x", [math.nan], error=error),
    ]
    for call in calls:
        with pytest.raises(error, match=r"^x(\[0\])? = .*: expected ") as caught:
            call()
        assert "\n" not in str(caught.value)
        assert isinstance(caught.value, ValueError)  # every project error is a ValueError too
