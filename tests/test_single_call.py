"""One state through :class:`vgtarm.Robot`: its single-state path (issue 35, item 1) gives the batch
path's numbers bit for bit and refuses exactly what the batch path refuses, with the same message.

The single-state path serves 1-D float64 arrays of the right length (``robot._single_states``);
a robot whose path is switched off (:func:`batch_only`) runs the same call through the batch
path, the oracle here: the same inputs, the same backend, the code of before. Every public method
that evaluates the model is compared on random valid states, on the compiled and the interpreted
paper robot and on a stack on the recursive model, and every kind of refusal (values not finite,
outside their range, legs that cannot be assembled, a memory limit, a result that is not finite,
dtypes and shapes the path does not serve) is compared message for message. On the compiled
backend the checks run in C (``vgt_single_call``, ``csrc/single.c``): its decisions are compared
with the NumPy checks the other backends run, on the same states.
"""

from __future__ import annotations

import dataclasses
import threading
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

import vgtarm
from vgtarm.errors import AssemblyError, ConfigError, InputError
from vgtarm.memory import LIMIT_VARIABLE
from vgtarm.model import interface
from vgtarm.model import robot as robot_module
from vgtarm.model.compiled import CompiledBackend, InterpretedBackend, build_functions
from vgtarm.model.robot import recursive_robot

from .conftest import random_configurations
from .test_api_inputs import METHODS as API_METHODS
from .test_recursive import configurations, varied_stack

#: Every public method of Robot that evaluates the model on one state, with its arguments: those
#: of test_api_inputs' table but the range and assembly predicates, which evaluate nothing.
METHODS: dict[str, tuple[str, ...]] = {
    name: labels
    for name, labels in API_METHODS.items()
    if name not in ("in_joint_range", "is_assemblable", "check_assembly")
}
STATES = 40


def batch_only(robot: vgtarm.Robot) -> vgtarm.Robot:
    """The same robot (parameters, backend) with its single-state path switched off."""
    slow = vgtarm.Robot(robot.parameters, robot.backend)
    slow._single_states = {method: (slow.backend, None) for method in METHODS}
    return slow


def arrays_of(result: Any) -> list[np.ndarray]:
    if dataclasses.is_dataclass(result):
        return [getattr(result, f.name) for f in dataclasses.fields(result)]
    return list(result) if isinstance(result, tuple | list) else [result]


def assert_same_bits(single: Any, batch: Any, what: str) -> None:
    for a, b in zip(arrays_of(single), arrays_of(batch), strict=True):
        assert type(a) is np.ndarray and a.dtype == np.float64, what
        assert a.shape == b.shape, (what, a.shape, b.shape)
        assert a.tobytes() == np.ascontiguousarray(b).tobytes(), what


def random_states(robot: vgtarm.Robot, n: int, seed: int) -> dict[str, np.ndarray]:
    """``n`` valid states: assemblable configurations inside the limits, rates, efforts, a tip force."""
    if robot.is_stack:
        q = configurations(robot.parameters, n, seed)
    else:
        q = random_configurations(robot, n, seed=seed)
    rng = np.random.default_rng(seed + 1)
    shape = q.shape
    return {
        "q": q,
        "qd": rng.normal(scale=0.5, size=shape),
        "qdd": rng.normal(scale=2.0, size=shape),
        "F": rng.normal(scale=50.0, size=shape),
        "f_tip": rng.normal(scale=20.0, size=(n, 3)),
    }


@pytest.fixture(scope="module")
def robots(robot: vgtarm.Robot) -> dict[str, vgtarm.Robot]:
    return {
        "compiled": robot,
        "interpreted": vgtarm.Robot(robot.parameters, InterpretedBackend(build_functions())),
        "recursive stack": recursive_robot(varied_stack(2)),
    }


def served(robot: vgtarm.Robot) -> list[str]:
    """The methods of METHODS whose function the robot's backend has."""
    names = robot._specs()
    found = []
    for method in METHODS:
        try:
            robot.backend.signature(names[method].function)
        except KeyError:
            continue
        found.append(method)
    return found


@pytest.mark.parametrize("kind", ["compiled", "interpreted", "recursive stack"])
def test_one_state_gives_the_batch_paths_numbers_bit_for_bit(robots, kind, monkeypatch):
    robot = robots[kind]
    slow = batch_only(robot)
    states = random_states(robot, STATES, seed=11)
    methods = served(robot)
    assert len(methods) >= (7 if kind == "recursive stack" else len(METHODS))

    def refuse(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("the single-state path took the batch path")

    for method in methods:
        args = [states[label] for label in METHODS[method]]
        batch = arrays_of(getattr(robot, method)(*args))
        with monkeypatch.context() as patch:
            patch.setattr(robot, "_evaluate", refuse)
            singles = [getattr(robot, method)(*[a[i] for a in args]) for i in range(STATES)]
        assert robot._single_states[method][1] is not None, method
        for i, single in enumerate(singles):
            assert_same_bits(single, [b[i] for b in batch], f"{kind} {method} state {i}")
            assert_same_bits(single, getattr(slow, method)(*[a[i] for a in args]), f"{kind} {method} {i}")


def test_the_results_are_fresh_arrays(robot):
    q = robot.parameters.home.copy()
    first = robot.mass_matrix(q)
    kinematics = robot.forward_kinematics(q)
    first[:] = np.nan
    kinematics.tip[:] = np.nan
    assert np.isfinite(robot.mass_matrix(q)).all()
    assert np.isfinite(robot.forward_kinematics(q).tip).all()
    assert robot.forward_kinematics(q).platform_position.flags.writeable


def test_the_default_tip_force_is_zero(robot):
    s = random_states(robot, 1, seed=3)
    q, qd, F = s["q"][0], s["qd"][0], s["F"][0]
    assert_same_bits(robot.forward_dynamics(q, qd, F), robot.forward_dynamics(q, qd, F, np.zeros(3)), "fd")
    assert_same_bits(robot.inverse_dynamics(q, qd, F), robot.inverse_dynamics(q, qd, F, np.zeros(3)), "id")


def outcome(action: Callable[[], Any]) -> tuple[str, Any]:
    """What a call gives: ``("raised", (type, message))`` or ``("returned", its arrays' bytes)``."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # neither path may warn (overflow, invalid value)
        try:
            result = action()
        except Exception as error:  # noqa: BLE001 - any refusal is compared, type and message
            return "raised", (type(error), str(error))
    return "returned", [(a.shape, a.tobytes()) for a in arrays_of(result)]


def valid(robot: vgtarm.Robot) -> dict[str, np.ndarray]:
    s = random_states(robot, 1, seed=5)
    return {label: value[0] for label, value in s.items()}


def with_element(args: dict[str, Any], label: str, index: int, value: Any) -> dict[str, Any]:
    changed = dict(args)
    array = np.array(changed[label], dtype=float)
    array[index] = value
    changed[label] = array
    return changed


def cases(robot: vgtarm.Robot) -> list[tuple[str, dict[str, Any]]]:
    """Inputs the batch path refuses (and a few it accepts) as 1-D float64 arrays or close to them."""
    good = valid(robot)
    low, high = robot.joint_range()
    limits = robot.input_ranges()
    found: list[tuple[str, dict[str, Any]]] = [("valid", good)]
    for label in ("q", "qd", "qdd", "F", "f_tip"):
        for value in (np.nan, np.inf, -np.inf, 1e308, -1.7976931348623157e308):
            found.append((f"{label} = {value}", with_element(good, label, 1, value)))
        top = limits[label][1][2]
        found.append((f"{label} at its bound", with_element(good, label, 2, top)))
        found.append((f"{label} beyond its bound", with_element(good, label, 2, np.nextafter(top, np.inf))))
    found.append(("q at its lowest", with_element(good, "q", 6, low[6])))
    found.append(("q below its lowest", with_element(good, "q", 6, np.nextafter(low[6], -np.inf))))
    found.append(("q a leg of zero", with_element(good, "q", 0, 0.0)))  # in range, cannot be assembled
    found.append(("q long diagonal", with_element(good, "q", 2, high[2])))
    found.append(("q too short", {**good, "q": good["q"][:-1]}))
    found.append(("q float32", {**good, "q": good["q"].astype(np.float32)}))
    found.append(("qd integers", {**good, "qd": np.zeros(7, dtype=int)}))
    found.append(("q complex", {**good, "q": good["q"].astype(complex)}))
    found.append(("q big-endian", {**good, "q": good["q"].astype(">f8")}))
    found.append(("q masked", {**good, "q": np.ma.masked_array(good["q"], mask=[1, 0, 0, 0, 0, 0, 0])}))
    found.append(("q strided", {**good, "q": np.repeat(good["q"], 2)[::2]}))
    found.append(("q a row", {**good, "q": good["q"][None]}))
    found.append(("q a list", {**good, "q": good["q"].tolist()}))
    found.append(("f_tip two", {**good, "f_tip": np.zeros(2)}))
    return found


def test_every_refusal_is_the_batch_paths_with_the_same_message(robot):
    slow = batch_only(robot)
    refused = 0
    for name, args in cases(robot):
        for method, labels in METHODS.items():
            values = [args[label] for label in labels]
            fast = outcome(lambda m=method, v=values: getattr(robot, m)(*v))
            oracle = outcome(lambda m=method, v=values: getattr(slow, m)(*v))
            assert fast == oracle, (name, method, fast, oracle)
            refused += fast[0] == "raised"
    assert refused >= 200  # the cases do reach the refusals (231 of 455 calls)


def test_margins_at_the_edge_of_assembly_are_decided_as_before(robot):
    """A diagonal within a few units of the last place of closing a triangle (``2b + v > p``): the
    single-state path leaves such margins to the batch path (below its trust), which decides as it
    always has; a margin of a nanometre is refused."""
    slow = batch_only(robot)
    q = valid(robot)["q"].copy()
    b = robot.parameters.b[0]
    q[0] = 0.5  # s long enough for the platform triangle
    decided = set()
    for v in (0.28, 0.3, 0.2999, 0.31):
        q[1] = v
        p = v + 2 * b
        for diagonal in (p, *np.nextafter(p, [0.0, 1.0]), p - 2e-16, p + 2e-16, p - 1e-13, p - 1e-9, p + 1e-9):
            q[2] = diagonal
            for method in ("forward_kinematics", "mass_matrix"):
                fast = outcome(lambda m=method: getattr(robot, m)(q))
                assert fast == outcome(lambda m=method: getattr(slow, m)(q)), (v, diagonal, method)
                decided.add(fast[0])
    assert decided == {"raised", "returned"}
    q[1], q[2] = 0.3, 0.3 + 2 * b + 1e-9
    with pytest.raises(AssemblyError, match="2b \\+ v > p"):
        robot.mass_matrix(q)


def test_a_memory_limit_applies_to_one_state_as_before(robot, monkeypatch):
    slow = batch_only(robot)
    good = valid(robot)
    args = (good["q"], good["qd"], good["F"])
    for limit in ("100", "300", "1M", "  ", "lots"):
        monkeypatch.setenv(LIMIT_VARIABLE, limit)
        for strided in (False, True):
            q = np.repeat(args[0], 2)[::2] if strided else args[0]
            fast = outcome(lambda q=q: robot.forward_dynamics(q, *args[1:]))
            assert fast == outcome(lambda q=q: slow.forward_dynamics(q, *args[1:])), (limit, strided)
    monkeypatch.setenv(LIMIT_VARIABLE, "100")
    with pytest.raises(InputError, match=r"^forward_dynamics: a batch of 1 rows needs about \d+ bytes"):
        robot.forward_dynamics(*args)
    monkeypatch.setenv(LIMIT_VARIABLE, "lots")
    with pytest.raises(ConfigError, match=LIMIT_VARIABLE):
        robot.mass_matrix(args[0])


def test_a_result_that_is_not_finite_is_refused_as_before(robot):
    """A robot whose bodies weigh next to nothing: its accelerations overflow."""
    light = feather(robot)
    args = (robot.parameters.home.copy(), np.zeros(7), np.full(7, 1e3))
    fast = outcome(lambda: light.forward_dynamics(*args))
    assert fast == outcome(lambda: batch_only(light).forward_dynamics(*args))
    assert fast[0] == "raised" and "the result is not finite" in fast[1][1]


def test_threads_calling_at_once_get_their_own_numbers(robot):
    states = random_states(robot, 8, seed=21)
    expected = robot.forward_dynamics(states["q"], states["qd"], states["F"], states["f_tip"])
    failures: list[str] = []

    def work(k: int) -> None:
        for _ in range(300):
            i = k % 8
            got = robot.forward_dynamics(states["q"][i], states["qd"][i], states["F"][i], states["f_tip"][i])
            if got.tobytes() != expected[i].tobytes():
                failures.append(f"thread {k}")
                return

    threads = [threading.Thread(target=work, args=(k,)) for k in range(8)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not failures
    assert len(robot._single_states["forward_dynamics"][1].frames) >= 1


def feather(robot: vgtarm.Robot) -> vgtarm.Robot:
    """The robot with bodies that weigh next to nothing: its accelerations overflow."""
    p = robot.parameters
    bodies = tuple(
        dataclasses.replace(b, mass=b.mass * 1e-300, inertia=tuple(tuple(x * 1e-300 for x in r) for r in b.inertia))
        for b in p.bodies
    )
    return robot.with_parameters(dataclasses.replace(p, bodies=bodies))


def test_the_compiled_robot_checks_one_state_in_c(robot):
    assert isinstance(robot.backend, CompiledBackend)
    ffi = robot.backend.ffi
    for method in METHODS:
        single = robot._single_state(method)
        assert single is not None, method
        _, run, _ = single.frame()
        assert ffi.typeof(run.args[0]) is ffi.typeof("vgt_single *"), method


def test_the_c_checks_decide_as_the_numpy_checks(robot, monkeypatch):
    """Every state of :func:`cases` (and an overflowing result) through the C driver and through the
    NumPy checks on the same robot: the same states are served, with the same numbers; the driver
    says why it declines the others."""
    status = interface.enum("vgt_single_status")
    heavy, light = robot, feather(robot)
    why: dict[tuple[str, str], str] = {}
    for name, args in [*cases(robot), ("overflow", {**valid(robot), "F": np.full(robot.n_joints, 1e3)})]:
        for method, labels in METHODS.items():
            who = light if name == "overflow" else heavy
            in_c = who._single_state(method)
            with monkeypatch.context() as patch:
                patch.setattr(robot_module, "checked_single_call", lambda *_: None)
                in_numpy = who._single_state(method)
            assert in_c is not None and in_numpy is not None
            values = tuple(args[label] for label in labels)
            fast, slow = in_c(values), in_numpy(values)
            assert (fast is None) == (slow is None), (name, method)
            if fast is not None:
                assert_same_bits(fast, slow, f"{name} {method}")
            views, run, _ = in_c.frame()
            if any(
                type(v) is not np.ndarray or v.shape != w.shape or v.dtype != np.float64
                for v, w in zip(values, views, strict=True)
            ):
                continue  # not served: never reaches the driver
            for view, value in zip(views, values, strict=True):
                view[...] = value
            code = run()
            assert (code == 0) == (fast is not None), (name, method, code)
            why[name, method] = next(k for k, v in status.items() if v == code)
    for method in METHODS:
        assert why["valid", method] == "VGT_SINGLE_DONE", method
        assert why["q = nan", method] == why["q beyond its bound", method] == "VGT_SINGLE_OUTSIDE", method
        assert why["q a leg of zero", method] == "VGT_SINGLE_MARGIN", method
    assert (
        why["F = inf", "forward_dynamics"] == why["f_tip beyond its bound", "inverse_dynamics"] == "VGT_SINGLE_OUTSIDE"
    )
    assert why["overflow", "forward_dynamics"] == "VGT_SINGLE_NOT_FINITE"
