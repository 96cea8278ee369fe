"""Single calls: one state through :class:`~vgtarm.model.robot.Robot`, against its core (issue 35, item 1).

For the paper's robot on its compiled library (and on CasADi's interpreter), and a two-module stack
on the recursive model, each method called on one state of 1-D float64 arrays (the single-state
path), against, in the same run and in turns:

- **core**: the model's function alone on one sample, on buffers prepared once
  (:func:`vgtarm.model.backends.single_call`: the compiled function called directly through cffi;
  for the other backends their ``evaluate`` of one row), no check of any input;
- **batch of one**: the same state as arrays of one row, ``(1, n)``, which take the batch path:
  what a single call cost before the single-state path (issue 35 measured 55 us for the forward
  dynamics);
- **Pinocchio**: ``constraintDynamics`` (one Python call) on the chain of the same shape as a
  two-module stack (:func:`benchmarks.bench_recursive.pinocchio_chain`: seven joints, a planar
  joint per module and a twist) with one 3-D loop constraint at its last body, and ``aba`` on the
  same chain. It is not a twin of the paper's robot (none is built here), only a measure of what
  one call of a compiled dynamics library's binding costs; absent without the ``bench`` extra.

Each variant is timed in rounds of about :data:`ROUND_SECONDS`, the variants of a method in turns
(so load from other processes falls on all of them alike); the figures are the median over
:data:`ROUNDS` rounds of the time per call, and the ratios are taken per round before their median.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np

import vgtarm
from vgtarm.model.backends import single_call

#: Timed rounds of each variant (taken in turns).
ROUNDS = 21
#: Length of one round (s).
ROUND_SECONDS = 0.02
#: The methods timed: (method, its compiled function, its arguments by name).
METHODS: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("forward_kinematics", "fk", ("q",)),
    ("tip_position", "tip", ("q",)),
    ("tip_jacobian", "jac", ("q",)),
    ("mass_matrix", "mass", ("q",)),
    ("bias_forces", "bias_forces", ("q", "qd")),
    ("forward_dynamics", "fd", ("q", "qd", "F", "f_tip")),
    ("inverse_dynamics", "id", ("q", "qd", "qdd", "f_tip")),
)

Call = Callable[[], object]


def _rounds(variants: dict[str, Call]) -> dict[str, list[float]]:
    """Seconds per call of each variant in each of :data:`ROUNDS` rounds, the variants in turns."""
    calls = {}
    for name, call in variants.items():
        call()
        start, count = time.perf_counter(), 0
        while time.perf_counter() - start < 0.005:
            call()
            count += 1
        calls[name] = max(1, int(count * ROUND_SECONDS / 0.005))
    times: dict[str, list[float]] = {name: [] for name in variants}
    for _ in range(ROUNDS):
        for name, call in variants.items():
            n = calls[name]
            start = time.perf_counter()
            for _ in range(n):
                call()
            times[name].append((time.perf_counter() - start) / n)
    return times


def _us(seconds: float) -> str:
    return f"{seconds * 1e6:.2f} us"


def _state(robot: vgtarm.Robot, seed: int) -> dict[str, np.ndarray]:
    """One valid state: near home, moving, with efforts and a tip force."""
    rng = np.random.default_rng(seed)
    n = robot.n_joints
    lower, upper = robot.joint_limits()
    q = robot.parameters.home + 0.05 * (upper - lower) * rng.uniform(-1.0, 1.0, n)
    return {
        "q": q,
        "qd": rng.normal(scale=0.1, size=n),
        "F": rng.normal(scale=20.0, size=n),
        "qdd": rng.normal(scale=0.5, size=n),
        "f_tip": rng.normal(scale=5.0, size=3),
    }


def _core(robot: vgtarm.Robot, function: str, args: list[np.ndarray]) -> Call:
    """The model's function alone on one sample, on buffers prepared once."""
    sig = robot.backend.signature(function)
    outputs = np.empty(sum(sig.nnz_out))
    return single_call(robot.backend, function, [*(a.copy() for a in args), robot.parameter_vector], outputs)


def _rows(label: str, robot: vgtarm.Robot, methods: tuple[tuple[str, str, tuple[str, ...]], ...]) -> None:
    """Print the table's rows of one robot."""
    state = _state(robot, 0)
    for method, function, labels in methods:
        args = [state[name] for name in labels]
        bound = getattr(robot, method)
        rows = [a[None] for a in args]
        times = _rounds(
            {
                "core": _core(robot, function, args),
                "robot": lambda b=bound, a=args: b(*a),
                "batch": lambda b=bound, a=rows: b(*a),
            }
        )
        core, single, batch = (statistics.median(times[k]) for k in ("core", "robot", "batch"))
        ratio = statistics.median(r / c for r, c in zip(times["robot"], times["core"], strict=True))
        before = statistics.median(b / c for b, c in zip(times["batch"], times["core"], strict=True))
        print(
            f"| {label} | `{method}` | {_us(core)} | {_us(single)} | **{ratio:.2f}** | {_us(batch)} | {before:.2f} "
            f"| {batch / single:.1f}x |",
            flush=True,
        )


def _pinocchio(paper: vgtarm.Robot) -> list[str] | None:
    """Rows of one ``constraintDynamics`` and one ``aba`` call (module docstring), timed in turns with
    the paper robot's forward dynamics and forward kinematics of one state."""
    try:
        from .bench_recursive import pinocchio_chain
        from .bench_stacks import family

        pin, model = pinocchio_chain(family(2))
    except ImportError:  # the extra `bench` (PyPI `pin`) is not installed
        return None
    p: Any = pin
    m: Any = model
    data = m.createData()
    rng = np.random.default_rng(0)
    q = p.randomConfiguration(m, -np.ones(m.nq), np.ones(m.nq))
    v, tau = rng.normal(scale=0.1, size=m.nv), rng.normal(scale=5.0, size=m.nv)
    where = p.SE3(np.eye(3), np.array([0.05, 0.02, 0.1]))
    constraint = p.RigidConstraintModel(p.ContactType.CONTACT_3D, m, m.njoints - 1, where, p.ReferenceFrame.LOCAL)
    models, datas = p.StdVec_RigidConstraintModel(), p.StdVec_RigidConstraintData()
    models.append(constraint)
    datas.append(constraint.createData())
    p.initConstraintDynamics(m, data, models, datas)
    prox = p.ProximalSettings(1e-12, 1e-10, 10)  # the planar chain leaves the loop's z redundant
    state = _state(paper, 0)
    times = _rounds(
        {
            "Pinocchio `constraintDynamics`": lambda: p.constraintDynamics(m, data, q, v, tau, models, datas, prox),
            "Pinocchio `aba`": lambda: p.aba(m, data, q, v, tau),
            "fd": lambda: paper.forward_dynamics(state["q"], state["qd"], state["F"], state["f_tip"]),
            "fk": lambda: paper.forward_kinematics(state["q"]),
        }
    )
    rows = []
    for name in ("Pinocchio `constraintDynamics`", "Pinocchio `aba`"):
        fd = statistics.median(a / b for a, b in zip(times["fd"], times[name], strict=True))
        fk = statistics.median(a / b for a, b in zip(times["fk"], times[name], strict=True))
        rows.append(f"| {name} | {_us(statistics.median(times[name]))} | **{fd:.2f}** | {fk:.2f} |")
    return rows


def run() -> None:
    """The tables (module docstring)."""
    from vgtarm.model.compiled import InterpretedBackend, build_functions
    from vgtarm.model.robot import recursive_robot

    from .bench_stacks import family

    print("\n### Single calls: one state through Robot, against its core\n")
    print(f"median of {ROUNDS} rounds of about {ROUND_SECONDS * 1e3:.0f} ms each, variants in turns\n")
    print(
        "| robot | method | core | Robot, one state | Robot / core | batch of one (the batch path) | batch / core "
        "| speed-up |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    paper = vgtarm.load_robot()
    _rows(f"paper robot ({paper.backend.kind})", paper, METHODS)
    interpreted = vgtarm.Robot(paper.parameters, InterpretedBackend(build_functions()))
    _rows("paper robot (interpreted)", interpreted, METHODS)
    stack = recursive_robot(family(2))
    _rows("2-module stack (recursive)", stack, METHODS)
    rows = _pinocchio(paper)
    if rows is None:
        print("\nPinocchio: not installed (the `bench` extra); no comparison with its binding.")
        return
    print("\nOne Python call of Pinocchio on the 7-joint chain of a two-module stack, in turns with the paper robot:\n")
    print("| call | time | Robot `forward_dynamics` / it | Robot `forward_kinematics` / it |")
    print("| --- | --- | --- | --- |")
    for row in rows:
        print(row)


if __name__ == "__main__":
    run()
