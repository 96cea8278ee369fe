"""Batches on several threads (issue 35, item 2): the same numbers bit for bit as on one thread.

Every public batched method of the :class:`~vgtarm.Robot` on both models (the paper's robot on its
compiled symbolic library, a 10-module stack on the recursive model), the recursive model's own
methods, and :func:`vgtarm.machine.split_rows` itself (each row once, errors raised, nested calls
on their own thread). The splitting is forced (two threads, tiny chunks, no minimum batch) so that
it runs on any machine; no test looks at a clock.
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import vgtarm
from vgtarm import machine
from vgtarm.errors import ConfigError
from vgtarm.model import compiled
from vgtarm.model.recursive import RecursiveModel
from vgtarm.model.robot import recursive_robot
from vgtarm.model.stack import Stack, load_stack

from .conftest import random_configurations

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
N = 300


@pytest.fixture
def forced(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Two threads, chunks of a few rows, no minimum: the threads used by each split, recorded."""
    monkeypatch.setenv(machine.THREADS_VARIABLE, "2")
    monkeypatch.setattr(machine, "MIN_PARALLEL_SECONDS", 0.0)
    monkeypatch.setattr(machine, "CHUNK_SECONDS", 1e-9)
    used: list[int] = []
    original = machine.split_rows

    def recorded(n: int, work: Callable[[int, int], None], threads: int | None = None) -> int:
        count = original(n, work, threads)
        used.append(count)
        return count

    monkeypatch.setattr(machine, "split_rows", recorded)
    for module in ("vgtarm.model.backends", "vgtarm.model.recursive.model"):
        monkeypatch.setattr(f"{module}.split_rows", recorded)
    return used


def ten_modules() -> Stack:
    """Ten paper modules, planes alternating, a twist stage after every second one (as the benchmarks')."""
    paper = load_stack(EXAMPLES / "paper_robot.toml")
    first, second = paper.modules
    assert second.twist is not None
    stage = dataclasses.replace(second.twist, height=0.06)
    modules = []
    for i in range(1, 11):
        twist = second.twist if i == 10 else (stage if i % 2 == 0 else None)
        modules.append(dataclasses.replace(first if i % 2 else second, twist=twist))
    return dataclasses.replace(paper, name="ten paper modules", modules=tuple(modules))


def assert_same(a: Any, b: Any) -> None:
    """Equal bit for bit: arrays, tuples of them, dataclasses of them."""
    if dataclasses.is_dataclass(a):
        for field in dataclasses.fields(a):
            assert_same(getattr(a, field.name), getattr(b, field.name))
    elif isinstance(a, tuple | list):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            assert_same(x, y)
    elif isinstance(a, dict):
        assert a.keys() == b.keys()
        for key in a:
            assert_same(a[key], b[key])
    else:
        x, y = np.asarray(a), np.asarray(b)
        assert x.shape == y.shape and x.dtype == y.dtype
        assert x.tobytes() == y.tobytes()


def robot_calls(robot: vgtarm.Robot, q: np.ndarray, seed: int) -> dict[str, Callable[[], Any]]:
    """Every public batched method of ``robot`` that its model has, on ``q`` and random rates."""
    rng = np.random.default_rng(seed)
    qd, qdd = rng.normal(scale=0.3, size=q.shape), rng.normal(scale=2.0, size=q.shape)
    F, f = rng.normal(scale=20.0, size=q.shape), rng.normal(scale=5.0, size=(len(q), 3))
    calls: dict[str, Callable[[], Any]] = {
        "forward_kinematics": lambda: robot.forward_kinematics(q),
        "tip_position": lambda: robot.tip_position(q),
        "tip_jacobian": lambda: robot.tip_jacobian(q),
        "angular_jacobian": lambda: robot.angular_jacobian(q),
        "tip_hessian": lambda: robot.tip_hessian(q),
        "tip_velocity": lambda: robot.tip_velocity(q, qd),
        "mass_matrix": lambda: robot.mass_matrix(q),
        "bias_forces": lambda: robot.bias_forces(q, qd),
        "forward_dynamics": lambda: robot.forward_dynamics(q, qd, F, f),
        "inverse_dynamics": lambda: robot.inverse_dynamics(q, qd, qdd, f),
        "is_assemblable": lambda: robot.is_assemblable(q),
        "evaluate ik_position": lambda: robot.evaluate("ik_position", {"q": q, "lam": f}, len(q)),
    }
    if robot.backend.kind != "recursive":  # the symbolic library's own functions
        calls["com_jacobians"] = lambda: robot.com_jacobians(q)
        calls["bias_accelerations"] = lambda: robot.bias_accelerations(q, qd)
        calls["energy"] = lambda: robot.energy(q, qd)
    return calls


def test_the_recursive_robot_gives_the_same_numbers_on_threads(forced):
    stack = ten_modules()
    threaded, single = recursive_robot(stack), recursive_robot(stack)
    single.backend.threads = 1  # type: ignore[attr-defined]
    rng = np.random.default_rng(3)
    span = stack.upper - stack.lower
    q = stack.home + 0.05 * span * rng.uniform(-1.0, 1.0, size=(N, stack.n_joints))
    one, many = robot_calls(single, q, 4), robot_calls(threaded, q, 4)
    for name in one:
        forced.clear()
        expected = one[name]()
        assert set(forced) <= {1}, name
        got = many[name]()
        assert max(forced, default=1) == 2 or name == "is_assemblable", name  # the threads did run
        assert_same(got, expected)


def test_the_recursive_model_gives_the_same_numbers_on_threads(forced):
    stack = ten_modules()
    rng = np.random.default_rng(5)
    span = stack.upper - stack.lower
    q = stack.home + 0.05 * span * rng.uniform(-1.0, 1.0, size=(N, stack.n_joints))
    qd, qdd = rng.normal(scale=0.3, size=q.shape), rng.normal(scale=2.0, size=q.shape)
    f, m = rng.normal(scale=5.0, size=(N, 3)), rng.normal(scale=1.0, size=(N, 3))
    one, many = RecursiveModel(stack), RecursiveModel(stack, threads=None)
    assert one.threads == 1  # the core's default: the calling thread alone
    for name, args in (
        ("tip_position", (q,)),
        ("forward_kinematics", (q,)),
        ("jacobians", (q,)),
        ("mass_matrix", (q,)),
        ("bias_forces", (q, qd)),
        ("inverse_dynamics", (q, qd, qdd, f, m)),
        ("forward_dynamics", (q, qd, qdd, f, m)),
    ):
        forced.clear()
        assert_same(getattr(many, name)(*args), getattr(one, name)(*args))
        assert max(forced) == 2, name
    assert many.with_gravity((0.0, 0.0, 0.0)).threads is None


def test_the_paper_robot_gives_the_same_numbers_on_threads(forced, robot):
    if not isinstance(robot.backend, compiled.CompiledBackend):
        pytest.skip("the compiled backend is not available")
    q = random_configurations(robot, N, seed=7)
    calls = robot_calls(robot, q, 8)
    backend = robot.backend
    try:
        for name, call in calls.items():
            backend.threads = 1
            forced.clear()
            expected = call()
            backend.threads = None
            got = call()
            assert max(forced, default=1) == 2 or name == "is_assemblable", name
            assert_same(got, expected)
    finally:
        backend.threads = None


def test_split_rows_covers_each_row_once_and_raises_the_first_error(forced):
    seen = np.zeros(1000, dtype=int)
    names: set[str] = set()
    lock = threading.Lock()

    def work(start: int, stop: int) -> None:
        with lock:
            seen[start:stop] += 1
            names.add(threading.current_thread().name)

    assert machine.split_rows(1000, work, 2) == 2
    assert (seen == 1).all()
    assert machine.split_rows(1000, work, 1) == 1 and (seen == 2).all()
    assert machine.split_rows(0, work, 2) == 1 and (seen == 2).all()

    def failing(start: int, stop: int) -> None:
        if start >= 500:
            raise MemoryError("no scratch")

    with pytest.raises(MemoryError, match="no scratch"):
        machine.split_rows(1000, failing, 2)

    inner: list[tuple[str, int]] = []

    def nested(start: int, stop: int) -> None:
        count = machine.split_rows(50, lambda a, b: None, 2)
        with lock:
            inner.append((threading.current_thread().name, count))

    machine.split_rows(200, nested, 2)
    assert inner  # the calling thread splits again, a worker does not
    assert all(count == (1 if name.startswith("vgtarm-batch") else 2) for name, count in inner)


def test_the_thread_count_comes_from_the_variable_or_the_cpus(monkeypatch):
    monkeypatch.setenv(machine.THREADS_VARIABLE, "3")
    assert machine.batch_threads() == 3
    monkeypatch.delenv(machine.THREADS_VARIABLE)
    assert machine.batch_threads() == min(machine.usable_cpus(), machine.MAX_BATCH_THREADS)
    monkeypatch.setenv(machine.THREADS_VARIABLE, "many")
    with pytest.raises(ConfigError, match="VGTARM_THREADS = 'many': expected a whole number"):
        machine.batch_threads()
    with pytest.raises(vgtarm.InputError, match="threads = 0"):
        RecursiveModel(ten_modules(), threads=0)
