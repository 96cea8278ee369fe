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
- **Pinocchio** (the anchor of issue 35's target: the paper robot's ``forward_dynamics`` at most
  half of it): ``constraintDynamics`` (one Python call) on the twin of the paper's robot
  (:func:`benchmarks.pinocchio_twin.build_twin`: the truss, each leg a revolute and a prismatic
  joint, 15 joints, its four loops closed by 3-D point constraints; its accelerations equal ours,
  ``tests/test_pinocchio_twin.py``) at the same state as ours, timed in turns with the Robot's
  ``forward_dynamics`` and its core. As a fair user would, the twin's data, constraint data and
  proximal settings are prepared once, and its state (``q``, ``v``, and ``tau``: our efforts less
  the viscous friction, plus ``J^T f`` of the tip force) is mapped once; the call's result is
  checked against ours before timing. Two proximal settings: the fastest that stays accurate (one
  iteration, ``mu = 1e-12``: the anchor) and the exact one (two iterations; Pinocchio's stopping
  test never passes on the loops' redundant rows, so it always runs them all;
  :data:`benchmarks.pinocchio_twin.PROXIMAL`). Absent without the ``bench`` extra.

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
    """Rows of one ``constraintDynamics`` call on the twin (module docstring), with the fastest accurate
    and the exact proximal settings, timed in turns with the paper robot's ``forward_dynamics`` and
    its core at the same state; the first row is the table's title."""
    try:
        from .pinocchio_twin import FASTEST, PROXIMAL, build_twin

        twin = build_twin(paper.parameters)
    except ImportError:  # the extra `bench` (PyPI `pin`) is not installed
        return None
    state = _state(paper, 0)
    q, qd, F, f = state["q"], state["qd"], state["F"], state["f_tip"]
    x = twin.configuration(q, paper.forward_kinematics(q).passive)
    v, tau = twin.velocity(x, qd), twin.efforts(x, qd, F, f)
    p: Any = twin.pin
    m: Any = twin.model
    ours = paper.forward_dynamics(q, qd, F, f)
    variants: dict[str, Call] = {}
    errors = []
    for label, proximal in (("one iteration, mu 1e-12", FASTEST), ("two iterations, mu 1e-8", PROXIMAL)):
        data, models, datas, settings = twin.prepare(proximal)
        theirs = np.asarray(p.constraintDynamics(m, data, x, v, tau, models, datas, settings))[twin.actuated]
        errors.append(f"{float(np.abs(theirs - ours).max() / np.abs(ours).max()):.1e} ({label})")
        name = f"Pinocchio `constraintDynamics`, twin, {label}"
        variants[name] = lambda d=data, c=models, e=datas, s=settings: p.constraintDynamics(m, d, x, v, tau, c, e, s)
    anchor = next(iter(variants))
    variants["Robot `forward_dynamics`"] = lambda: paper.forward_dynamics(q, qd, F, f)
    variants["its core (`fd`)"] = _core(paper, "fd", [state[k] for k in ("q", "qd", "F", "f_tip")])
    times = _rounds(variants)
    rows = [
        f"The anchor: one Python call of Pinocchio's `constraintDynamics` on the twin of the paper robot "
        f"({m.nv} joints, {len(twin.constraints)} 3-D loop constraints), in turns with the paper robot's forward "
        "dynamics at the same state:\n"
    ]
    for name, series in times.items():
        ratio = statistics.median(a / b for a, b in zip(series, times[anchor], strict=True))
        rows.append(f"| {name} | {_us(statistics.median(series))} | **{ratio:.2f}** |")
    rows.append(f"\nThe twin's accelerations of our joints at this state, from ours (relative): {', '.join(errors)}.")
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
    print("\n" + rows[0])
    print("| call | time | / Pinocchio (one iteration) |")
    print("| --- | --- | --- |")
    for row in rows[1:]:
        print(row)


if __name__ == "__main__":
    run()
