"""The recursive model of a stack (issue 24) from 1 to 50 modules, against the symbolic model and Pinocchio.

Run with ``python -m benchmarks recursive`` (a minute), and at the end of ``python -m benchmarks
stacks``. The robots are :func:`benchmarks.bench_stacks.family` (``k`` paper modules, planes
alternating 0 and 90 degrees, a twist stage after every second module and the paper's twist on
the last). Figures, all in this process and run:

- **build**: the recursive model's one library compiled cold into a fresh temporary cache folder,
  in a process of its own (wall time and that process's peak memory, compiler included), which then
  makes the 50-module arm and evaluates it; then **a second arm** (another process on the same
  folder: import, load, the 50-module arm's model made and evaluated once), and the making of one
  arm's model in this process (its data arrays: nothing is compiled per arm);
- **forward dynamics per sample**, batches of configurations within a tenth of each joint's span
  around home: the recursive model (articulated bodies, C; its batches run eight samples side by
  side in the lanes of vectors, issue 35, and are timed with the lanes off too, one sample at a
  time as before them: ``vgt_rec_lanes(0)``), the symbolic model's compiled library
  where the cache already holds it (the structures of 2 and 6 modules; building the others takes
  minutes to hours and is what ``python -m benchmarks stacks`` measures), and **Pinocchio**'s
  articulated-body algorithm (``abaInParallel`` on one thread: its batched C++ entry point) on a
  serial chain with the same number of degrees of freedom and bodies: one planar joint (two
  translations, one rotation, as a module's platform moves) per module, one revolute joint per
  twist, bodies of the same masses and inertias;
- the growth exponent ``a`` of ``y ~ n^a`` between 10 and 50 modules;
- **control** (:func:`control_figures`): the inverse kinematics of the whole case-1 path (placed
  and scaled to the arm, :func:`vgtarm.experiment.cases.case_path`; the fast solver with exact rates) and
  computed force control of it in the compiled closed loop, on the recursive model at 6, 10 and 50
  modules, beside the symbolic library at 6 modules where the cache holds it; the loop's speed as
  simulated time over wall time (real-time factor). On the recursive model each run is timed
  with the fused step and with the previous implementation (``RecursiveBackend(stack,
  fused=False)``), alternating, the best of :data:`CFC_REPEATS` each, and their results compared
  bit for bit.

Times are CPU time of this process (``time.process_time``): on a machine shared with other work,
wall time counts the waits for a busy core; both are printed for the recursive model.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from vgtarm.model.compiled import library_cached
from vgtarm.model.definition import StackDefinition
from vgtarm.model.recursive import RecursiveModel
from vgtarm.model.stack import Stack

from .bench_stacks import family
from .common import _fmt

MODULE_COUNTS = (1, 2, 4, 6, 8, 10, 15, 20, 30, 40, 50)
SAMPLES = 20_000
TARGETS = {"fd10": 5e-6, "fd50": 30e-6, "growth": 1.3, "build": 15.0, "memory": 500e6, "second": 1.0}
_SCRIPT = """
import sys, time
start = time.perf_counter()
sys.path.insert(0, {root!r})
import numpy as np
from benchmarks.bench_stacks import family
from vgtarm.model.recursive import RecursiveModel
stack = family(50)
model = RecursiveModel(stack)
model.forward_dynamics(stack.home, np.zeros(stack.n_joints), np.zeros(stack.n_joints))
import re, resource
# VmHWM: this process's own peak (ru_maxrss of a process started by a large one reports the
# parent's size at the fork); the compiler's, started by this small process, from ru_maxrss
status = open("/proc/self/status").read()
own = int(re.search(r"VmHWM:\\s+(\\d+)", status).group(1))
peak = max(own, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
print(time.perf_counter() - start, peak * 1024)
"""


def _inputs(stack: Stack, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    span = stack.upper - stack.lower
    q = stack.home + 0.1 * span * rng.uniform(-1.0, 1.0, size=(n, stack.n_joints))
    return q, rng.normal(scale=0.1, size=q.shape), rng.normal(scale=50.0, size=q.shape)


def _per_sample(call: Callable[[], object], n: int, clock: Callable[[], float] = time.process_time) -> float:
    """Best of five timings of ``call`` (a batch of ``n``), per sample."""
    call()
    best = math.inf
    for _ in range(5):
        start = clock()
        call()
        best = min(best, clock() - start)
    return best / n


def _in_process(env: dict[str, str]) -> tuple[float, float, float]:
    """Wall time, the child's own figure (s) and the peak memory (bytes: the largest of the process
    and of its compiler) of one run of :data:`_SCRIPT`."""
    root = str(Path(__file__).resolve().parents[1])
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-c", _SCRIPT.format(root=root)], env=env, capture_output=True, text=True, check=True
    )
    wall = time.perf_counter() - start
    inside, peak = (float(x) for x in done.stdout.strip().splitlines()[-1].split())
    return wall, inside, peak


def _build_figures() -> dict[str, float]:
    with tempfile.TemporaryDirectory(prefix="vgtarm-bench-recursive-") as folder:
        os.chmod(folder, 0o700)
        env = {**os.environ, "VGTARM_CACHE_DIR": folder}
        cold_wall, _, cold_peak = _in_process(env)
        second_wall, second_inside, _ = _in_process(env)
    stack = family(50)
    start = time.perf_counter()
    RecursiveModel(stack)
    made = time.perf_counter() - start
    return {
        "cold": cold_wall,
        "cold_peak": cold_peak,
        "second": second_wall,
        "second_inside": second_inside,
        "made": made,
    }


def pinocchio_chain(stack: Stack) -> tuple[object, object]:
    """A Pinocchio model of the same chain shape: a planar joint per module, a revolute joint per twist."""
    import pinocchio as pin

    model = pin.Model()
    parent = 0
    for k, module in enumerate(stack.modules):
        placement = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.28]))
        parent = model.addJoint(parent, pin.JointModelPlanar(), placement, f"module{k + 1}")
        body = module.platform
        model.appendBodyToJoint(
            parent, pin.Inertia(body.mass, np.array(body.com), np.array(body.inertia)), pin.SE3.Identity()
        )
        if module.twist is not None:
            parent = model.addJoint(parent, pin.JointModelRZ(), pin.SE3.Identity(), f"twist{k + 2}")
            twist = module.twist.body
            if twist is not None:
                model.appendBodyToJoint(
                    parent, pin.Inertia(twist.mass, np.array(twist.com), np.array(twist.inertia)), pin.SE3.Identity()
                )
    ee = stack.end_effector
    model.appendBodyToJoint(parent, pin.Inertia(ee.mass, np.array(ee.com), np.array(ee.inertia)), pin.SE3.Identity())
    return pin, model


def _pinocchio_per_sample(stack: Stack, n: int) -> tuple[float, float]:
    """Pinocchio's ABA per sample: batched (``abaInParallel``, one thread) and one Python call per sample."""
    try:
        pin, model = pinocchio_chain(stack)
    except ImportError:  # the extra `bench` (PyPI `pin`) is not installed
        return math.nan, math.nan
    assert model.nv == stack.n_joints  # type: ignore[attr-defined]
    rng = np.random.default_rng(1)
    q = np.column_stack([pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq)) for _ in range(n)])  # type: ignore[attr-defined]
    v = rng.normal(scale=0.1, size=(model.nv, n))  # type: ignore[attr-defined]
    tau = rng.normal(scale=5.0, size=(model.nv, n))  # type: ignore[attr-defined]
    pool = pin.ModelPool(model, 1)  # type: ignore[attr-defined]
    out = np.zeros((model.nv, n))  # type: ignore[attr-defined]
    batched = _per_sample(lambda: pin.abaInParallel(1, pool, q, v, tau, out), n)  # type: ignore[attr-defined]
    data = model.createData()  # type: ignore[attr-defined]
    m = min(n, 2000)
    columns = [(q[:, i].copy(), v[:, i].copy(), tau[:, i].copy()) for i in range(m)]

    def loop() -> None:
        for a, b, c in columns:
            pin.aba(model, data, a, b, c)  # type: ignore[attr-defined]

    return batched, _per_sample(loop, m)


def _without_lanes(model: RecursiveModel, call: Callable[[], object], n: int) -> float:
    """:func:`_per_sample` of ``call`` with the batches' vector lanes off (one sample at a time)."""
    model._lib.vgt_rec_lanes(0)
    try:
        return _per_sample(call, n)
    finally:
        model._lib.vgt_rec_lanes(-1)


def _growth(x: list[float], y: list[float]) -> float:
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def _row(k: int) -> dict[str, float]:
    """The figures of ``k`` modules."""
    import vgtarm

    stack = family(k)
    model = RecursiveModel(stack)
    q, qd, F = _inputs(stack, SAMPLES)
    row: dict[str, float] = {"k": k, "n": stack.n_joints, "bodies": model.n_bodies}
    row["fd"] = _per_sample(lambda: model.forward_dynamics(q, qd, F), SAMPLES)
    row["fd_wall"] = _per_sample(lambda: model.forward_dynamics(q, qd, F), SAMPLES, time.perf_counter)
    row["id"] = _per_sample(lambda: model.inverse_dynamics(q, qd, F), SAMPLES)
    row["fd_one"] = _without_lanes(model, lambda: model.forward_dynamics(q, qd, F), SAMPLES)
    row["id_one"] = _without_lanes(model, lambda: model.inverse_dynamics(q, qd, F), SAMPLES)
    m = max(SAMPLES // k, 200)
    row["mass"] = _per_sample(lambda: model.mass_matrix(q[:m]), m)
    row["mass_one"] = _without_lanes(model, lambda: model.mass_matrix(q[:m]), m)
    row["symbolic"] = math.nan
    if library_cached(StackDefinition.of(stack)):
        robot = vgtarm.Robot(stack)
        row["symbolic"] = _per_sample(lambda: robot.forward_dynamics(q, qd, F), SAMPLES)
    row["pinocchio"], row["pinocchio_loop"] = _pinocchio_per_sample(stack, SAMPLES)
    symbolic = _fmt(row["symbolic"]) if math.isfinite(row["symbolic"]) else "-"
    print(
        f"  {k} modules ({stack.n_joints} joints): FD {_fmt(row['fd'])} (one at a time {_fmt(row['fd_one'])}), "
        f"ID {_fmt(row['id'])} (one at a time {_fmt(row['id_one'])}), "
        f"M {_fmt(row['mass'])} (one at a time {_fmt(row['mass_one'])}), symbolic FD {symbolic}, "
        f"Pinocchio ABA {_fmt(row['pinocchio'])}",
        flush=True,
    )
    return row


#: Module counts of the control figures: IK of case 1 and CFC of it (the 50-module arm's IK of the
#: whole path did not finish in minutes before the saddle-free continuation and the coarse step scaled
#: with the reach, docs/ik.md; it is timed now); at :data:`LOOP_ONLY` modules the loop alone, on a
#: joint reference of small sinusoids about home for case 1's 6.283 s.
CONTROL_COUNTS = (6, 10, 20, 50)
LOOP_ONLY = (50,)
TARGETS.update(cfc10=100.0, cfc50=1.0, ik50=30.0)


#: Runs of CFC timed per implementation (the best of them is reported; the two alternate).
CFC_REPEATS = 3


def _cfc_times(robots: dict[str, Any], reference: Any) -> dict[str, Any]:
    """CFC of ``reference`` (case 1's gains) on each robot, alternating, :data:`CFC_REPEATS` times:
    the best wall and CPU seconds of each and its last result."""
    from vgtarm.experiment.cases import run_case

    best: dict[str, Any] = {name: [math.inf, math.inf, None] for name in robots}
    for _ in range(CFC_REPEATS):
        for name, robot in robots.items():
            wall, cpu = time.perf_counter(), time.process_time()
            result = run_case(robot, 1, reference=reference)
            wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
            entry = best[name]
            entry[0], entry[1], entry[2] = min(entry[0], wall), min(entry[1], cpu), result
    return best


def _robots(stack: Stack, model: str) -> dict[str, Any]:
    """The robots whose loops are timed: the symbolic library's, or the recursive model's fused step
    and the previous implementation (its separate adapters) beside it."""
    from vgtarm.model.recursive.backend import RecursiveBackend
    from vgtarm.model.robot import Robot

    if model == "symbolic":
        return {"symbolic": Robot(stack)}
    return {
        "fused": Robot(stack, RecursiveBackend(stack)),
        "previous": Robot(stack, RecursiveBackend(stack, fused=False)),
    }


def _timed_row(k: int, n: int, robots: dict[str, Any], reference: Any, ik: tuple[float, float]) -> dict[str, float]:
    from vgtarm.simulation.result import SimulationResult

    times = _cfc_times(robots, reference)
    name = next(iter(robots))
    cfc, cfc_cpu, result = times[name]
    assert isinstance(result, SimulationResult)
    simulated = float(result.t[-1] - result.t[0])
    row = {
        "k": k,
        "n": n,
        "ik": ik[0],
        "ik_cpu": ik[1],
        "cfc": cfc,
        "cfc_cpu": cfc_cpu,
        "rtf": simulated / cfc,
        "rtf_cpu": simulated / cfc_cpu,
        "error": float(result.tip_error.max()),
    }
    if "previous" in times:
        before, before_cpu, old = times["previous"]
        same = all(
            np.array_equal(getattr(old, f), getattr(result, f), equal_nan=True) for f in ("q", "qd", "effort", "tip")
        )
        row.update(
            before=before,
            before_cpu=before_cpu,
            rtf_before_cpu=simulated / before_cpu,
            speedup_cpu=before_cpu / cfc_cpu,
            speedup=before / cfc,
            same=float(same),
        )
    print(
        f"  {name} {k} modules: CFC {cfc:.3f} s wall ({cfc_cpu:.3f} s CPU) for {simulated:.2f} s simulated "
        f"({row['rtf']:.0f}x real time wall, {row['rtf_cpu']:.0f}x CPU), max tip error {row['error']:.2e} m"
        + (
            f"; previous implementation {row['before']:.3f} s wall ({row['before_cpu']:.3f} s CPU): "
            f"{row['speedup_cpu']:.2f}x by CPU, {row['speedup']:.2f}x wall, results bit for bit: {bool(row['same'])}"
            if "before" in row
            else ""
        ),
        flush=True,
    )
    return row


def _control_row(k: int, model: str) -> dict[str, float]:
    """IK of case 1 and CFC of it on ``family(k)`` with ``model``: wall and CPU seconds, real-time factor."""
    from vgtarm.experiment.cases import case_path
    from vgtarm.simulation.reference import JointReference

    stack = family(k)
    if model == "symbolic" and not library_cached(StackDefinition.of(stack)):
        return {"k": k, "n": stack.n_joints, "ik": math.nan, "cfc": math.nan}
    robots = _robots(stack, model)
    robot = next(iter(robots.values()))
    path = case_path(robot, 1)
    wall, cpu = time.perf_counter(), time.process_time()
    ik = robot.inverse_kinematics(path)
    ik_wall, ik_cpu = time.perf_counter() - wall, time.process_time() - cpu
    print(f"  {model} {k} modules: IK {ik_wall:.2f} s wall ({ik_cpu:.2f} s CPU)", flush=True)
    reference = JointReference.of(ik, name="case 1")
    row = _timed_row(k, stack.n_joints, robots, reference, (ik_wall, ik_cpu))
    row["ik_ok"] = float(bool(ik.success))
    return row


def _loop_row(k: int) -> dict[str, float]:
    """CFC in the compiled loop on ``family(k)`` (recursive) along sinusoids about home: loop speed only."""
    from vgtarm.simulation.reference import JointReference

    stack = family(k)
    robots = _robots(stack, "recursive")
    robot = robots["fused"]
    t = np.arange(6284, dtype=np.float64) * 1e-3
    span = (stack.upper - stack.lower) * 0.05
    phase = np.linspace(0.0, np.pi, stack.n_joints)
    w = 2 * np.pi / 6.283
    q = stack.home + span * np.sin(w * t[:, None] + phase)
    qd = span * w * np.cos(w * t[:, None] + phase)
    qdd = -span * w * w * np.sin(w * t[:, None] + phase)
    reference = JointReference(t=t, q=q, qd=qd, qdd=qdd, rates="exact", name="sinusoids", tip=robot.tip_position(q))
    return _timed_row(k, stack.n_joints, robots, reference, (math.nan, math.nan))


def _paper_ik() -> tuple[float, float]:
    """The baseline of the IK rows, in the same run: the paper's robot's IK of case 1 (the fast solver,
    exact rates), CPU and wall seconds, best of 3."""
    import vgtarm
    from vgtarm import paths

    robot = vgtarm.load_robot()
    path = paths.case1(dt=1e-3)
    robot.inverse_kinematics(path)  # warm
    best = (math.inf, math.inf)
    for _ in range(3):
        wall, cpu = time.perf_counter(), time.process_time()
        robot.inverse_kinematics(path)
        best = min(best, (time.process_time() - cpu, time.perf_counter() - wall))
    return best


def control_figures() -> list[dict[str, Any]]:
    """The control rows (module docstring), printed as a table."""
    paper_cpu, paper_wall = _paper_ik()
    print(f"  baseline: the paper's robot, IK of case 1: {paper_cpu:.3f} s CPU ({paper_wall:.3f} s wall)")
    rows: list[dict[str, Any]] = [dict(_control_row(6, "symbolic"), model="symbolic")]
    rows += [dict(_control_row(k, "recursive"), model="recursive") for k in CONTROL_COUNTS]
    rows += [dict(_loop_row(k), model="recursive") for k in LOOP_ONLY]
    print("\n### Inverse kinematics and computed force control of case 1 (same run)\n")
    print(
        "| model | modules | joints | IK of the whole path (wall) | IK CPU | CFC of the path (wall) | CFC CPU "
        "| real time / wall | real time / CPU | previous implementation CPU (its real time) | speed-up CPU, wall "
        "| max tip error | IK CPU / paper robot's |"
    )
    print("|" + " --- |" * 13)
    for r in rows:
        if not math.isfinite(r["cfc"]):
            print(f"| {r['model']} | {r['k']:.0f} | {r['n']:.0f} | not in the cache | | | | | | | | | |")
            continue
        ik = (
            f"{r['ik']:.2f} s | {r['ik_cpu']:.2f} s"
            if math.isfinite(r["ik"])
            else "(loop only: sinusoids about home) | -"
        )
        ratio = f"{r['ik_cpu'] / paper_cpu:.0f}x" if math.isfinite(r["ik"]) else "-"
        before = (
            f"{r['before_cpu']:.3f} s ({r['rtf_before_cpu']:.0f}x) | {r['speedup_cpu']:.2f}x, {r['speedup']:.2f}x"
            if "before" in r
            else "- | -"
        )
        print(
            f"| {r['model']} | {r['k']:.0f} | {r['n']:.0f} | {ik} | {r['cfc']:.3f} s | {r['cfc_cpu']:.3f} s | "
            f"{r['rtf']:.0f}x | {r['rtf_cpu']:.0f}x | {before} | {r['error']:.2e} m | {ratio} |"
        )
    print(f"\nBaseline (same run): the paper's robot's IK of case 1, {paper_cpu:.3f} s CPU, {paper_wall:.3f} s wall.")
    verified = all(r.get("ik_ok", 1.0) == 1.0 for r in rows if math.isfinite(r.get("ik", math.nan)))
    print(f"Every IK verified on every sample: {verified}.")
    return rows


def run() -> list[dict[str, float]]:
    rows = [_row(k) for k in MODULE_COUNTS]
    build = _build_figures()
    _print(rows, build)
    control_figures()
    return rows


def _print(rows: list[dict[str, float]], build: dict[str, float]) -> None:
    print("\n### The recursive model, 1 to 50 modules (per sample, CPU time; ratios in the same run)\n")
    print(
        "| modules | joints | bodies | forward dynamics (ABA) | wall | one sample at a time "
        "| inverse dynamics (RNEA) | one sample at a time | M (CRBA) | one sample at a time "
        "| symbolic library FD | symbolic / recursive | Pinocchio ABA, batched | recursive / Pinocchio "
        "| Pinocchio ABA, one Python call each |"
    )
    print("|" + " --- |" * 15)
    for r in rows:
        sym = r["symbolic"]
        sym_cells = f"{_fmt(sym)} | {sym / r['fd']:.1f}x" if math.isfinite(sym) else "- | -"
        print(
            f"| {r['k']:.0f} | {r['n']:.0f} | {r['bodies']:.0f} | {_fmt(r['fd'])} | {_fmt(r['fd_wall'])} | "
            f"{_fmt(r['fd_one'])} | {_fmt(r['id'])} | {_fmt(r['id_one'])} | {_fmt(r['mass'])} | "
            f"{_fmt(r['mass_one'])} | {sym_cells} | "
            f"{_fmt(r['pinocchio'])} | "
            f"{r['fd'] / r['pinocchio']:.2f}x | {_fmt(r['pinocchio_loop'])} |"
        )
    big = [r for r in rows if r["k"] >= 10]
    growth = _growth([r["n"] for r in big], [r["fd"] for r in big])
    pin_growth = _growth([r["n"] for r in big], [r["pinocchio"] for r in big])
    by_k = {int(r["k"]): r for r in rows}
    print("\n| figure | measured | target |")
    print("| --- | --- | --- |")
    print(f"| forward dynamics, 10 modules (35 joints) | {_fmt(by_k[10]['fd'])} | <= 5 us |")
    print(f"| forward dynamics, 50 modules (175 joints) | {_fmt(by_k[50]['fd'])} | <= 30 us |")
    print(f"| growth exponent of FD, 10 to 50 modules | {growth:.2f} (Pinocchio {pin_growth:.2f}) | <= 1.3 |")
    print(f"| recursive / Pinocchio ABA at 50 modules | {by_k[50]['fd'] / by_k[50]['pinocchio']:.2f}x | <= 3x |")
    for k in (10, 50):
        r = by_k[k]
        print(
            f"| recursive in lanes / Pinocchio ABA (batched, one thread) at {k} modules | "
            f"{r['fd'] / r['pinocchio']:.2f}x (one sample at a time {r['fd_one'] / r['pinocchio']:.2f}x) | <= 0.8x |"
        )
    print(
        f"| cold build of the one library + 50-module arm, own process (wall, peak memory) | "
        f"{build['cold']:.1f} s, {build['cold_peak'] / 1e6:.0f} MB | <= 15 s, <= 500 MB |"
    )
    print(
        f"| a second arm, own process: start, import, load, make, evaluate (wall; inside the process) | "
        f"{build['second']:.2f} s; {build['second_inside']:.2f} s | <= 1 s |"
    )
    print(f"| making one 50-module arm's model in a running process | {build['made'] * 1e3:.2f} ms | |")


if __name__ == "__main__":
    run()
