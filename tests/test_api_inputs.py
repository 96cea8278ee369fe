"""Every public method of :class:`vgtarm.Robot` refuses what is not an input of the model (issue 20, item 8).

Complex values (even with a zero imaginary part), booleans, ``None``, text, nested lists, values
that are not finite or lie outside the accepted physical ranges (:mod:`vgtarm.model.sanity`) and
batches that will not fit in memory end in one :class:`~vgtarm.errors.InputError` line (a
:class:`~vgtarm.errors.VgtarmError` and a ``ValueError``) that names the argument and shows the
user's own value; anything accepted gives finite results, bit for bit those of the compiled
functions. Hypothesis runs derandomized, as in ``test_fuzz.py``.
"""

from __future__ import annotations

import dataclasses
import math
import re
import tracemalloc
import warnings
from collections.abc import Callable
from decimal import Decimal
from fractions import Fraction
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import vgtarm
from vgtarm import paths
from vgtarm.errors import AssemblyError, InputError, VgtarmError
from vgtarm.memory import LIMIT_VARIABLE
from vgtarm.model import sanity
from vgtarm.model.factors import MODEL_FACTOR_RANGE, model_factor
from vgtarm.model.sanity import SANE_EFFORT, SANE_RAMP, SANE_SPEED

from .conftest import random_configurations

MESSAGE_LIMIT = 400


def fuzz(examples: int) -> Any:
    """Reproducible settings without a per-example deadline (as ``test_fuzz.fuzz``)."""
    return settings(
        max_examples=examples,
        deadline=None,
        derandomize=True,
        database=None,
        suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    )


#: Every public method of Robot that takes numbers, with its arguments in order (``f_tip`` last).
METHODS: dict[str, tuple[str, ...]] = {
    "forward_kinematics": ("q",),
    "tip_position": ("q",),
    "tip_jacobian": ("q",),
    "tip_hessian": ("q",),
    "angular_jacobian": ("q",),
    "com_jacobians": ("q",),
    "mass_matrix": ("q",),
    "in_joint_range": ("q",),
    "is_assemblable": ("q",),
    "check_assembly": ("q",),
    "tip_velocity": ("q", "qd"),
    "bias_accelerations": ("q", "qd"),
    "bias_forces": ("q", "qd"),
    "energy": ("q", "qd"),
    "forward_dynamics": ("q", "qd", "F", "f_tip"),
    "inverse_dynamics": ("q", "qd", "qdd", "f_tip"),
}


def good_inputs(robot: vgtarm.Robot) -> dict[str, list[float]]:
    """A valid value of each argument: home at rest, holding still, no tip force."""
    q = robot.parameters.home
    return {
        "q": q.tolist(),
        "qd": [0.0] * 7,
        "qdd": [0.0] * 7,
        "F": robot.bias_forces(q, np.zeros(7)).tolist(),
        "f_tip": [0.0, 0.0, -20.0],
    }


def call(robot: vgtarm.Robot, method: str, arguments: dict[str, Any]) -> Any:
    return getattr(robot, method)(*[arguments[label] for label in METHODS[method]])


def arrays_of(result: Any) -> list[np.ndarray]:
    """The arrays of a method's result (a record, a tuple, an array or None)."""
    if result is None:
        return []
    if dataclasses.is_dataclass(result):
        return [np.asarray(getattr(result, f.name)) for f in dataclasses.fields(result)]
    if isinstance(result, tuple):
        return [np.asarray(r) for r in result]
    return [np.asarray(result)]


def assert_refused_or_finite(action: Callable[[], Any], argument: str) -> None:
    """``action`` either returns finite numbers or raises one short line of the project's hierarchy
    that names ``argument``; it never warns (no ComplexWarning, no overflow)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            result = action()
        except (InputError, AssemblyError) as error:
            message = str(error)
            assert isinstance(error, VgtarmError) and isinstance(error, ValueError)
            assert "\n" not in message and len(message) <= MESSAGE_LIMIT, message
            assert message.isprintable(), message
            assert re.match(rf"{argument}( must |: )", message), (argument, message)
            return
    for array in arrays_of(result):
        assert array.dtype == bool or np.isfinite(array).all(), (argument, array)


# -- what users type ------------------------------------------------------------------------------------

BAD_ELEMENTS = st.one_of(
    st.sampled_from(
        [
            1e308,
            -1e308,
            1e200,
            1e13,
            -1e13,
            10**400,
            -(10**30),
            math.inf,
            -math.inf,
            math.nan,
            1 + 1j,
            0.28 + 0j,
            complex(math.nan, 0.0),
            None,
            "0.28",
            "",
            b"1",
            True,
            False,
            [0.28, 0.28],
            [[0.28]],
            [],
            {},
            Decimal("0.28"),
            Decimal("1e400"),
            Decimal("NaN"),
            Fraction(1, 3),
            np.float32(np.inf),
            np.int64(2**62),
            np.complex128(0.3),
            np.longdouble("1e400") if np.finfo(np.longdouble).max > 1e400 else 1e308,
        ]
    ),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(10**400), max_value=10**400),
    st.complex_numbers(allow_nan=True, allow_infinity=True),
    st.text(max_size=5),
)

#: Whole arguments that are not an array of numbers of the right shape.
BAD_ARGUMENTS = st.sampled_from(
    [None, "home", b"", 0.28, True, 1j, [], [[]], [0.28] * 6, [[0.28] * 7, [0.28] * 6], {"q": 1}, object(), [None] * 7]
)


@fuzz(600)
@given(
    method=st.sampled_from(sorted(METHODS)),
    position=st.integers(min_value=0, max_value=6),
    element=BAD_ELEMENTS,
    batch=st.booleans(),
    data=st.data(),
)
def test_one_bad_element_is_refused_with_its_argument_or_gives_finite_results(
    robot, method: str, position: int, element: Any, batch: bool, data: Any
) -> None:
    arguments = good_inputs(robot)
    argument = data.draw(st.sampled_from(METHODS[method]))
    value = list(arguments[argument])
    value[position % len(value)] = element
    arguments[argument] = [arguments[argument], value] if batch else value
    assert_refused_or_finite(lambda: call(robot, method, arguments), argument)


@fuzz(200)
@given(method=st.sampled_from(sorted(METHODS)), bad=BAD_ARGUMENTS, data=st.data())
def test_a_bad_whole_argument_is_refused_with_its_name(robot, method: str, bad: Any, data: Any) -> None:
    arguments: dict[str, Any] = good_inputs(robot)
    argument = data.draw(st.sampled_from(METHODS[method]))
    if argument == "f_tip" and bad is None:
        return  # the default: no tip force
    arguments[argument] = bad
    with pytest.raises(InputError) as info:
        call(robot, method, arguments)
    message = str(info.value)
    assert "\n" not in message and len(message) <= MESSAGE_LIMIT
    assert re.match(rf"{argument}( must |: )", message), (argument, message)


@fuzz(300)
@given(
    method=st.sampled_from(["forward_dynamics", "inverse_dynamics", "bias_forces", "energy", "tip_velocity"]),
    scale=st.floats(min_value=-1.0, max_value=1.0),
    exponent=st.floats(min_value=-3.0, max_value=400.0),
    data=st.data(),
)
def test_rates_efforts_and_forces_are_refused_beyond_their_range_and_finite_inside(
    robot, method: str, scale: float, exponent: float, data: Any
) -> None:
    """Any finite value of any one input: refused (naming it) outside its range, finite results inside."""
    arguments: dict[str, Any] = good_inputs(robot)
    argument = data.draw(st.sampled_from(METHODS[method][1:]))
    value = scale * 10.0**exponent if exponent < 308 else scale * 1e308
    position = data.draw(st.integers(min_value=0, max_value=len(arguments[argument]) - 1))
    arguments[argument][position] = value
    low, high = robot.input_ranges()[argument]
    inside = low[position] <= value <= high[position]
    if inside:
        for array in arrays_of(call(robot, method, arguments)):
            assert np.isfinite(array).all()
    else:
        with pytest.raises(InputError, match=rf"^{argument}: .* is outside the accepted range"):
            call(robot, method, arguments)


def test_every_input_at_its_bounds_at_once_gives_finite_dynamics(robot):
    """Signs at random, every rate, acceleration, effort and tip force at its bound."""
    q = random_configurations(robot, 500, seed=3, margin=0.0)
    ranges = robot.input_ranges()
    rng = np.random.default_rng(4)

    def at_bounds(label: str) -> np.ndarray:
        high = ranges[label][1]
        return rng.choice([-1.0, 1.0], size=(len(q), len(high))) * high

    qd, qdd, F, f = at_bounds("qd"), at_bounds("qdd"), at_bounds("F"), at_bounds("f_tip")
    for result in (
        robot.forward_dynamics(q, qd, F, f),
        robot.inverse_dynamics(q, qd, qdd, f),
        robot.bias_forces(q, qd),
        *robot.energy(q, qd),
        *robot.tip_velocity(q, qd),
        robot.bias_accelerations(q, qd).com,
    ):
        assert np.isfinite(result).all()


# -- the examples of the issue -----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("value", "shown"),
    [
        ("complex", r"q\[6\] \(psi3\) = 0\.5j is complex \(pass q\.real if its real part is meant\)"),
        ("zero imaginary", r"q\[0\] \(s1\) = \(0\.28\d*\+0j\) is complex"),
        ("numpy complex", r"q\[0\] \(s1\) = \(0\.28\d*\+0j\) is complex"),
    ],
)
def test_complex_joint_values_are_refused_even_with_a_zero_imaginary_part(robot, value, shown):
    q = robot.parameters.home
    given = {
        "complex": [*q[:6], 0.5j],
        "zero imaginary": [complex(x) for x in q],
        "numpy complex": q.astype(complex),
    }[value]
    with pytest.raises(InputError, match=rf"^q must be real numbers; {shown}") as info:
        robot.forward_kinematics(given)
    assert "\n" not in str(info.value)


def test_none_is_shown_as_none_not_as_nan(robot):
    with pytest.raises(InputError, match=r"^q must be real numbers; q\[0\] \(s1\) = None is not a number$"):
        robot.tip_position([None] * 7)
    with pytest.raises(InputError, match=r"qd\[1, 3\] \(s2\) = None is not a number"):
        robot.bias_forces(robot.parameters.home, [[0.0] * 7, [0.0, 0.0, 0.0, None, 0.0, 0.0, 0.0]])


@pytest.mark.parametrize(
    ("element", "what"),
    [("0.3", r"'0\.3' is text"), (b"0", r"b'0' is text"), (object, r"is not a number"), (None, "None is not a number")],
)
def test_other_objects_are_named_with_the_users_value(robot, element, what):
    """NumPy would turn ``[0.28, '0.3', ...]`` into text throughout: the message shows the user's element."""
    q = list(robot.parameters.home)
    q[2] = element
    with pytest.raises(InputError, match=rf"^q must be real numbers; q\[2\] \(p1\) = .*{what}"):
        robot.mass_matrix(q)


def test_booleans_are_refused_where_the_array_holds_them(robot):
    """An array of booleans (or a list of them, or one among other objects) is refused; a list
    mixing a boolean with numbers is one of numbers to NumPy (True is 1.0), and taken as such."""
    with pytest.raises(InputError, match=r"^q must be real numbers; q\[0\] \(s1\) = True is a boolean"):
        robot.mass_matrix([True] * 7)
    with pytest.raises(InputError, match=r"q\[0\] \(s1\) = True is a boolean"):
        robot.mass_matrix(np.ones(7, dtype=bool))
    with pytest.raises(InputError, match=r"q\[1\] \(v1\) = False is a boolean"):
        robot.mass_matrix([0.3, False, None, 0.3, 0.3, 0.3, 0.0])


@pytest.mark.parametrize(
    ("argument", "value", "match"),
    [
        ("F", 1e308, r"^F: s1 = 1e\+308 N is outside the accepted range \[-1e\+12, 1e\+12\] N"),
        ("qd", 1e308, r"^qd: s1 = 1e\+308 m/s is outside the accepted range \[-140000, 140000\] m/s"),
        ("f_tip", -1e20, r"^f_tip: x = -1e\+20 N is outside the accepted range"),
        ("F", math.inf, r"^F must be finite; F\[0\] \(s1\) = inf$"),
        ("qd", 10**400, r"^qd: s1 = 1000000000\d*\.\.\. \(\d+ more characters\) m/s is outside"),
    ],
)
def test_forward_dynamics_refuses_huge_efforts_velocities_and_forces(robot, argument, value, match):
    arguments: dict[str, Any] = good_inputs(robot)
    arguments[argument][0] = value
    with pytest.raises(InputError, match=match):
        call(robot, "forward_dynamics", arguments)


def test_the_twist_takes_turns_per_second_and_efforts_newton_metres(robot):
    qd = np.zeros(7)
    qd[6] = 1e7
    with pytest.raises(
        InputError, match=r"qd: psi3 = 10000000\.0 rad/s is outside the accepted range \[-6\.28319e\+06"
    ):
        robot.bias_forces(robot.parameters.home, qd)
    F = np.zeros(7)
    F[6] = -2e12
    with pytest.raises(InputError, match=r"F: psi3 = -2000000000000\.0 N m is outside"):
        robot.forward_dynamics(robot.parameters.home, np.zeros(7), F)
    qdd = np.zeros((2, 7))
    qdd[1, 4] = 1e13
    with pytest.raises(InputError, match=r"qdd: v2 = 10000000000000\.0 m/s\^2 \(configuration \(1,\)\) is outside"):
        robot.inverse_dynamics(robot.parameters.home, np.zeros(7), qdd)


def test_the_ranges_are_the_documented_ones(robot):
    ranges = robot.input_ranges()
    span = robot.parameters.upper - robot.parameters.lower
    np.testing.assert_array_equal(ranges["q"][0], robot.joint_range()[0])
    np.testing.assert_allclose(ranges["qd"][1], SANE_SPEED * span)
    np.testing.assert_allclose(ranges["qdd"][1], SANE_SPEED * span / SANE_RAMP)
    assert (ranges["F"][1] == SANE_EFFORT).all() and (ranges["f_tip"][1] == SANE_EFFORT).all()
    assert ranges["qd"][1][0] == pytest.approx(1.4e5) and ranges["qd"][1][6] == pytest.approx(2e6 * math.pi)
    for low, high in ranges.values():
        np.testing.assert_array_equal(low[low < 0], -high[low < 0])
    assert SANE_RAMP == paths.MIN_DT  # the finest sample spacing a path accepts
    ranges["qd"][1][0] = 0.0  # a copy: the robot keeps its own
    assert robot.input_ranges()["qd"][1][0] > 0


# -- results ---------------------------------------------------------------------------------------


def test_valid_inputs_give_the_compiled_functions_numbers_bit_for_bit(robot):
    q = random_configurations(robot, 200, seed=5)
    rng = np.random.default_rng(6)
    qd, F, f = rng.normal(size=(200, 7)), rng.normal(scale=50.0, size=(200, 7)), rng.normal(size=3)
    p = robot.parameter_vector
    (M,) = robot.backend.evaluate("mass", [q, p], 200)
    np.testing.assert_array_equal(robot.mass_matrix(q), M.reshape(200, 7, 7))
    (qdd,) = robot.backend.evaluate("fd", [q, qd, F, f, p], 200)
    np.testing.assert_array_equal(robot.forward_dynamics(q, qd, F, f), qdd)
    np.testing.assert_array_equal(robot.forward_dynamics(q.tolist(), qd.tolist(), F.tolist(), f.tolist()), qdd)
    as_ints = np.round(q * 0).astype(int) + 1  # integers are real numbers: converted, not refused
    assert robot.in_joint_range(as_ints).dtype == bool


def test_a_result_that_is_not_finite_names_what_drove_it(robot):
    """A robot whose bodies weigh next to nothing: the accelerations of 1 kN overflow."""
    p = robot.parameters
    light = dataclasses.replace(
        p,
        bodies=tuple(
            dataclasses.replace(b, mass=b.mass * 1e-300, inertia=tuple(tuple(x * 1e-300 for x in r) for r in b.inertia))
            for b in p.bodies
        ),
    )
    feather = robot.with_parameters(light)
    home = p.home
    with pytest.raises(InputError, match=r"forward_dynamics: the result is not finite .*parameters of robot") as info:
        feather.forward_dynamics(home, np.zeros(7), np.full(7, 1e3))
    assert "\n" not in str(info.value)
    with pytest.raises(
        InputError, match=r"for configuration \(0,\) .*F\[\d\] \(\w+\) = 1e\+12 N drove it out of range"
    ):
        feather.forward_dynamics(np.tile(home, (2, 1)), np.zeros(7), np.full(7, 1e12))


# -- batches: memory, empty, broadcast -------------------------------------------------------------------


BATCH_CALLS: dict[str, Callable[[vgtarm.Robot, np.ndarray], Any]] = {
    name: (lambda robot, q, name=name: call(robot, name, {**good_inputs(robot), "q": q})) for name in METHODS
}


@pytest.mark.parametrize("method", sorted(METHODS))
def test_a_billion_rows_are_refused_before_anything_is_allocated(robot, method, monkeypatch):
    """A broadcast view of 1e9 configurations costs nothing; the method must refuse it from the
    estimate (here against 4 GB), allocating next to nothing."""
    monkeypatch.setenv(LIMIT_VARIABLE, "4G")
    huge = np.broadcast_to(robot.parameters.home, (10**9, 7))
    tracemalloc.start()
    try:
        with pytest.raises(InputError) as info:
            BATCH_CALLS[method](robot, huge)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    message = str(info.value)
    assert message.startswith(f"{method}: a batch of 1,000,000,000 rows needs about "), message
    assert f"more than the 4 GB set by {LIMIT_VARIABLE}; evaluate it in parts of at most " in message
    assert "\n" not in message
    assert peak < 10**7, peak  # nothing of the batch's size


def test_the_limit_is_the_machines_without_the_variable(robot, monkeypatch):
    monkeypatch.delenv(LIMIT_VARIABLE, raising=False)
    huge = np.broadcast_to(robot.parameters.home, (10**7, 10**6, 7))  # 1e13 rows: more than any machine has
    with pytest.raises(InputError, match=r"mass_matrix: a batch of 10,000,000,000,000 rows needs about .* TB"):
        robot.mass_matrix(huge)


def test_a_batch_that_fits_the_limit_runs_and_one_that_does_not_is_refused(robot, monkeypatch):
    monkeypatch.setenv(LIMIT_VARIABLE, "1M")
    q = random_configurations(robot, 3000, seed=7)
    with pytest.raises(
        InputError, match=r"mass_matrix: a batch of 3,000 rows needs about .* MB .* at most 1,\d\d\d rows"
    ):
        robot.mass_matrix(q)
    assert robot.mass_matrix(q[:100]).shape == (100, 7, 7)


def test_broadcast_operands_multiply_the_rows(robot, monkeypatch):
    """q of 1e5 and qd of 1e5 rows on separate axes are 1e10 rows together."""
    monkeypatch.setenv(LIMIT_VARIABLE, "4G")
    q = np.broadcast_to(robot.parameters.home, (10**5, 1, 7))
    qd = np.broadcast_to(np.zeros(7), (10**5, 7))
    with pytest.raises(InputError, match=r"forward_dynamics: a batch of 10,000,000,000 rows"):
        robot.forward_dynamics(q, qd, np.zeros(7))


@pytest.mark.parametrize("method", sorted(METHODS))
def test_an_empty_batch_gives_empty_results(robot, method):
    result = BATCH_CALLS[method](robot, np.zeros((0, 7)))
    for array in arrays_of(result):
        assert array.shape[0] == 0


def test_broadcasting_and_its_refusal(robot):
    q = np.tile(robot.parameters.home, (5, 1, 1))  # (5, 1, 7)
    qd = np.zeros((4, 7))
    assert robot.bias_forces(q, qd).shape == (5, 4, 7)
    with pytest.raises(
        InputError, match=r"^bias_forces: leading shapes do not broadcast: q \(5, 1, 7\), qd \(3, 2, 7\)$"
    ):
        robot.bias_forces(q, np.zeros((3, 2, 7)))


# -- the generic evaluate and the other arguments -------------------------------------------------------


@pytest.mark.parametrize(
    ("inputs", "n", "match"),
    [
        ({"q": [0.3 + 1j] * 7}, 1, r"mass input q must be real numbers; .*\(0\.3\+1j\) is complex"),
        ({"q": [None] * 7}, 1, r"mass input q must be real numbers; .* = None is not a number"),
        ({"q": [math.nan] * 7}, 1, r"mass input q must be finite; q\[0\] = nan"),
        ({"q": np.zeros((2, 7))}, 3, r"mass input q: expected shape \(3, 7\) or \(7,\), got \(2, 7\)"),
        ({"q": np.zeros(7)}, True, r"evaluate: n = True: expected a number of samples"),
        ({"q": np.zeros(7)}, -1, r"evaluate: n = -1"),
        ([("q", np.zeros(7))], 1, r"evaluate: inputs = \[.*expected a mapping"),
    ],
)
def test_evaluate_refuses_what_is_not_an_input(robot, inputs, n, match):
    with pytest.raises(InputError, match=match) as info:
        robot.evaluate("mass", inputs, n)
    assert "\n" not in str(info.value)


def test_evaluate_refuses_a_billion_rows_up_front(robot, monkeypatch):
    monkeypatch.setenv(LIMIT_VARIABLE, "4G")
    with pytest.raises(InputError, match=r"evaluate mass: a batch of 1,000,000,000 rows needs about 392 GB"):
        robot.evaluate("mass", {"q": np.broadcast_to(robot.parameters.home, (10**9, 7))}, 10**9)


@pytest.mark.parametrize("margin", [math.nan, math.inf, "0", None, True, 1j])
def test_is_assemblable_refuses_a_margin_that_is_not_a_length(robot, margin):
    with pytest.raises(InputError, match=r"^margin = "):
        robot.is_assemblable(robot.parameters.home, margin)


def test_joint_values_not_finite_are_false_for_in_joint_range_but_not_a_number_is_refused(robot):
    q = np.tile(robot.parameters.home, (2, 1))
    q[1, 0] = np.nan
    assert robot.in_joint_range(q).tolist() == [True, False]
    with pytest.raises(InputError, match="q must be real numbers"):
        robot.in_joint_range([None] * 7)


# -- the model factors -------------------------------------------------------------------------------


@pytest.mark.parametrize("value", [1e308, 1e-300, 1e4, 1e-4, math.nan, math.inf, 0, -1.0, 10**400, True, "2", None, 1j])
def test_a_model_factor_outside_its_range_names_the_value_and_the_range(value):
    with pytest.raises(
        InputError, match=r"^scaled: mass = .*: expected a factor in \[0\.001, 1000\] \(the model's mass"
    ) as info:
        model_factor("mass", value)
    assert "not finite" not in str(info.value)


@pytest.mark.parametrize(
    "value", [1, 1.1, 0.9, MODEL_FACTOR_RANGE[0], MODEL_FACTOR_RANGE[1], np.float32(2.0), Fraction(1, 2)]
)
def test_a_model_factor_inside_its_range_is_accepted(value):
    assert model_factor("inertia", value) == float(value)


def test_sanity_exports_what_the_robot_uses():
    assert sanity.FORCE_NAMES == ("x", "y", "z")
    assert set(sanity.RANGE_REASONS) == {"qd", "qdd", "F", "f_tip"}
