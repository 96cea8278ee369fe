"""Threads: the Robot over its one-thread core (issue 35, item 2).

For the paper's robot (its compiled symbolic library) and the stacks of 10 and 50 modules
(:func:`benchmarks.bench_stacks.family`, on the recursive model), a batch of 2,000 states: the
wall and CPU time per state of a :class:`~vgtarm.model.robot.Robot` method against the one-thread
core under it (the compiled backend with ``threads = 1``; :class:`RecursiveModel`, whose default is
one thread), and the Robot held to one thread (what its checks of the input cost), as ratios in
the same run; first on the quiet machine, then while a busy loop (another Python process) holds
one core.

The measurement runs in a child process whose environment leaves NumPy's BLAS at its default
thread count, as a user's script has it (``python -m benchmarks`` holds BLAS to one thread, which
hid the cause: the margin check's product woke OpenBLAS's threads, which then spun). The core and
the Robot are timed in turns, best of :data:`ROUNDS`, wall (``perf_counter``) and CPU
(``process_time``: every thread of the process) each.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

#: States per batch.
BATCH = 2000
#: Timed rounds of each variant (the best is kept), taken in turns.
ROUNDS = 7
#: Module counts of the stacks (the paper's robot comes first).
MODULES = (10, 50)


def _time(call: Callable[[], object], calls: int) -> tuple[float, float]:
    wall, cpu = time.perf_counter(), time.process_time()
    for _ in range(calls):
        call()
    return time.perf_counter() - wall, time.process_time() - cpu


def _compare(variants: Variants, per_call: float) -> dict[str, tuple[float, float]]:
    """Best wall and CPU time per state of each variant, timed in turns."""
    calls = max(1, int(0.05 / per_call))
    for call in variants.values():
        call()
    best = {name: (float("inf"), float("inf")) for name in variants}
    for _ in range(ROUNDS):
        for name, call in variants.items():
            wall, cpu = _time(call, calls)
            best[name] = (min(best[name][0], wall / calls / BATCH), min(best[name][1], cpu / calls / BATCH))
    return best


Variants = dict[str, Callable[[], object]]


def _cases() -> list[tuple[str, str, Variants, float]]:
    """(robot, method, {core, robot on one thread, robot}, seconds per call) of every row."""
    import numpy as np

    import vgtarm
    from vgtarm.model.recursive import RecursiveModel
    from vgtarm.model.robot import recursive_robot

    from .bench_stacks import family

    rng = np.random.default_rng(0)
    cases: list[tuple[str, str, Variants]] = []
    paper = vgtarm.load_robot()
    backend = paper.backend
    q = paper.parameters.home + rng.uniform(-0.01, 0.01, size=(BATCH, 7))
    qd, F = rng.normal(size=q.shape), rng.normal(scale=5.0, size=q.shape)
    p, f = paper.parameter_vector, np.zeros(3)

    def core(name: str, *inputs: object) -> Callable[[], object]:
        def call() -> object:
            backend.threads = 1
            try:
                return backend.evaluate(name, [*inputs, p], BATCH)  # type: ignore[list-item]
            finally:
                backend.threads = None

        return call

    def one(method: Callable[..., object], *args: object) -> Callable[[], object]:
        def call() -> object:
            backend.threads = 1
            try:
                return method(*args)
            finally:
                backend.threads = None

        return call

    for method, name, args in (
        ("forward_dynamics", "fd", (q, qd, F, f)),
        ("inverse_dynamics", "id", (q, qd, F, f)),
        ("tip_jacobian", "jac", (q,)),
    ):
        bound = getattr(paper, method)
        plain = args[:3] if method != "tip_jacobian" else args
        variants = {"core": core(name, *args), "one": one(bound, *plain), "robot": lambda b=bound, a=plain: b(*a)}
        cases.append(("paper robot", method, variants))
    for k in MODULES:
        stack = family(k)
        robot, model = recursive_robot(stack), RecursiveModel(stack)
        single = recursive_robot(stack)
        single.backend.threads = 1  # type: ignore[attr-defined]
        span = stack.upper - stack.lower
        qs = stack.home + 0.1 * span * rng.uniform(-1.0, 1.0, size=(BATCH, stack.n_joints))
        qds, Fs = rng.normal(scale=0.1, size=qs.shape), rng.normal(scale=50.0, size=qs.shape)
        label = f"{k} modules ({stack.n_joints} joints)"
        jacobian = model.jacobians
        for method, core_call, args in (
            ("forward_dynamics", model.forward_dynamics, (qs, qds, Fs)),
            ("inverse_dynamics", model.inverse_dynamics, (qs, qds, Fs)),
            ("tip_jacobian", lambda x, j=jacobian: j(x)[0], (qs,)),
        ):
            mine, theirs = getattr(single, method), getattr(robot, method)
            variants = {
                "core": lambda c=core_call, a=args: c(*a),
                "one": lambda m=mine, a=args: m(*a),
                "robot": lambda m=theirs, a=args: m(*a),
            }
            cases.append((label, method, variants))
    out = []
    for label, method, variants in cases:
        start = time.perf_counter()
        variants["core"]()
        out.append((label, method, variants, time.perf_counter() - start))
    return out


def _load() -> str:
    return Path("/proc/loadavg").read_text().split()[0] if Path("/proc/loadavg").exists() else "?"


def _table(title: str, cases: list[tuple[str, str, Variants, float]]) -> None:
    print(f"\n#### {title} (load average {_load()} at the start)\n")
    print(
        "| robot | method | core wall | core CPU | Robot wall | Robot CPU | wall ratio | CPU ratio "
        "| Robot on one thread: wall, CPU ratio |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for label, method, variants, per_call in cases:
        best = _compare(variants, per_call)
        (cw, cc), (rw, rc), (ow, oc) = best["core"], best["robot"], best["one"]
        print(
            f"| {label} | `{method}` | {cw * 1e6:.2f} us | {cc * 1e6:.2f} us | {rw * 1e6:.2f} us | {rc * 1e6:.2f} us "
            f"| **{rw / cw:.2f}** | **{rc / cc:.2f}** | {ow / cw:.2f}, {oc / cc:.2f} |",
            flush=True,
        )


def child() -> None:
    from threadpoolctl import threadpool_info

    from vgtarm.machine import batch_threads

    cases = _cases()
    pools = [i for i in threadpool_info() if i["user_api"] == "blas"]
    blas = ", ".join(f"{i['internal_api']} {i['num_threads']} threads" for i in pools)
    print(f"batch of {BATCH} states; Robot threads: {batch_threads()}; NumPy's BLAS: {blas or 'none found'}")
    _table("Quiet (no process of this benchmark besides it)", cases)
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        time.sleep(0.5)
        _table("While a busy loop (another process) holds one core", cases)
    finally:
        busy.kill()
        busy.wait()


def run() -> None:
    """The tables (module docstring), measured in a child process with NumPy's BLAS at its default."""
    print("\n### Threads: Robot over its one-thread core\n")
    unset = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS")
    env = {k: v for k, v in os.environ.items() if k not in unset}
    root = str(Path(__file__).resolve().parents[1])
    env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
    subprocess.run([sys.executable, "-c", "from benchmarks.bench_threads import child; child()"], env=env, check=True)


if __name__ == "__main__":
    run()
