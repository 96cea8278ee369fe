"""Switching control's GA exported (issue 25): the time of an activation in the exported C.

For each variant (``paper``, ``safe``) of case 2's switching control: the export's GA
(``vgtc_ga.c``) compiled as its Makefile does by default (-O2 -march=native), the same with clang
when it is installed, and, for comparison, at the portable -O2 (SSE2 only: every fmaf a libm
call), run on the same activations as the
simulation's compiled GA (``ga.c``, one thread: the baseline of the same run): windows of case
2's reference from states 0.3 mm / 3 mm/s off it, every ``k``-th sample, each with its own seed.
Every activation's gains are checked equal between the two (bit for bit). The times are measured
in C around each call (``harness/ga_harness.c``) and in Python around the simulation's call.
``VGTARM_BENCH_EXPORT_GA_N`` sets the activations per variant (default 1000).
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

import vgtarm
from vgtarm.control import SwitchingControl
from vgtarm.experiment.cases import case_study, joint_reference
from vgtarm.export import CompiledExport, export_controller, simulate_exported
from vgtarm.export.galoop import FLAGS, ExportedGA
from vgtarm.model.closedloop import ClosedLoopDriver
from vgtarm.model.compiled import CompiledBackend
from vgtarm.simulation import simulate
from vgtarm.simulation.engines import compiled_ga
from vgtarm.simulation.simulator import loop_arrays

#: The export's Makefile default for a switching export (shared-library form).
NATIVE = ("-std=c99", "-O2", "-march=native", "-fPIC", "-shared", "-ffp-contract=off")


def _percentiles(seconds: np.ndarray) -> str:
    p50, p99, p999 = np.percentile(seconds, [50, 99, 99.9]) * 1e3
    return f"{p50:.3f} ms | {p99:.3f} ms | {p999:.3f} ms | {seconds.max() * 1e3:.3f} ms"


def run() -> dict[str, dict[str, float]]:
    count = int(os.environ.get("VGTARM_BENCH_EXPORT_GA_N", "1000"))
    case = case_study(2)
    robot = vgtarm.load_robot()
    assert isinstance(robot.backend, CompiledBackend), "the benchmark compares compiled GAs: a C compiler is needed"
    backend = robot.backend
    reference = joint_reference(robot, 2, duration=4.0)
    n = len(reference.t)
    rng = np.random.default_rng(0)
    ks = np.linspace(0, n - 2, count).astype(int)
    q0 = reference.q[ks] + rng.normal(scale=3e-4, size=(count, 7))
    qd0 = reference.qd[ks] + rng.normal(scale=3e-3, size=(count, 7))
    seeds = rng.integers(0, 2**63, size=count)
    out: dict[str, dict[str, float]] = {}
    print(f"\n### The exported GA of switching control (case 2, {count} activations per variant)\n")
    print("| variant | build | p50 | p99 | p99.9 | max | over 1 ms | equal to ga.c |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for variant in ("paper", "safe"):
        scm = case.controller("scm", variant=variant)
        assert isinstance(scm, SwitchingControl)
        arrays = loop_arrays(robot, robot, reference, initial_state=(reference.q[0], reference.qd[0]))
        simulation = compiled_ga(scm, ClosedLoopDriver(backend), robot, arrays, reference.dt)
        simulation._ga.threads = 1
        horizons = np.minimum(scm.horizon, n - 1 - ks)
        inp = arrays.inputs
        rows = np.hstack([inp["q_d"], inp["qd_d"], inp["qdd_d"]])
        baseline = np.empty(count)
        genes = np.empty((count, 2 * 49))
        for i, k in enumerate(ks):
            started = time.perf_counter()
            genes[i] = simulation.activate(int(k), q0[i], qd0[i], int(seeds[i])).genes
            baseline[i] = time.perf_counter() - started
        print(
            f"| {variant} | simulation's ga.c, 1 thread (baseline) | {_percentiles(baseline)} |"
            f" {(baseline > 1e-3).sum()} | |"
        )
        with tempfile.TemporaryDirectory(prefix="vgtc-ga-bench-") as scratch:
            folder = export_controller(robot, Path(scratch) / variant, kp=case.kp, kv=case.kv, switching=scm).folder
            builds: list[tuple[str | None, str, tuple[str, ...]]] = [(None, "-O2 -march=native (Makefile)", NATIVE)]
            if shutil.which("clang"):
                builds.append(("clang", "clang -O2 -march=native", NATIVE))
            builds.append((None, "-O2 portable", FLAGS))
            for compiler, name, flags in builds:
                done = ExportedGA(folder, compiler=compiler, flags=flags).run(
                    ks, horizons, q0, qd0, rows, inp["tip_d"], seeds
                )
                equal = int(sum(np.array_equal(a, b) for a, b in zip(done.genes, genes, strict=True)))
                ratio = np.median(done.seconds) / np.median(baseline)
                print(
                    f"| {variant} | export, {name} | {_percentiles(done.seconds)} |"
                    f" {(done.seconds > 1e-3).sum()} | {equal} of {count}; median {ratio:.2f}x ga.c's |"
                )
                out[f"{variant} {name}"] = {
                    "p50": float(np.median(done.seconds)),
                    "p99": float(np.percentile(done.seconds, 99)),
                    "max": float(done.seconds.max()),
                }
        out[f"{variant} ga.c"] = {"p50": float(np.median(baseline)), "max": float(baseline.max())}
    out.update(_in_the_loop(case, robot))
    return out


def _in_the_loop(case: Any, robot: vgtarm.Robot) -> dict[str, dict[str, float]]:
    """Case 2 with the tool force, the whole run, closed through the export built -O2
    -march=native: the time of each period with an activation (GA and CFC step, measured in C)
    against simulate's own activations (ga.c, one thread), the same activations."""
    duration = float(os.environ.get("VGTARM_BENCH_EXPORT_GA_SECONDS", "4.0"))
    reference = joint_reference(robot, 2, duration=duration)
    out: dict[str, dict[str, float]] = {}
    print(f"\n#### In the loop: case 2 with the tool force, {duration:g} s, every activation\n")
    print(
        "| variant | activations | simulate (ga.c, 1 thread) p50 / p99 / max | export p50 / p99 / max |"
        " export over 1 ms | efforts equal |"
    )
    print("| --- | --- | --- | --- | --- | --- |")
    for variant in ("paper", "safe"):
        scm = case.controller("scm", variant=variant)
        previous = os.environ.get("VGTARM_THREADS")
        os.environ["VGTARM_THREADS"] = "1"
        try:
            theirs = simulate(robot, reference, scm, external_force=case.external_force)
        finally:
            if previous is None:
                del os.environ["VGTARM_THREADS"]
            else:
                os.environ["VGTARM_THREADS"] = previous
        with tempfile.TemporaryDirectory(prefix="vgtc-ga-loop-") as scratch:
            folder = export_controller(robot, Path(scratch) / variant, kp=case.kp, kv=case.kv, switching=scm).folder
            compiled = CompiledExport(folder, extra_flags=("-march=native",))
            mine = simulate_exported(compiled, robot, reference, external_force=case.external_force, controller=scm)
        a = np.array([x.wall_time_s for x in theirs.activations])
        b = np.array([x.wall_time_s for x in mine.activations])
        cells = [
            " / ".join(f"{v * 1e3:.3f}" for v in (np.median(t), np.percentile(t, 99), t.max())) + " ms" for t in (a, b)
        ]
        print(
            f"| {variant} | {len(b)} | {cells[0]} | {cells[1]} | {(b > 1e-3).sum()} |"
            f" {np.array_equal(mine.effort, theirs.effort)} |"
        )
        out[f"{variant} loop"] = {"p50": float(np.median(b)), "p99": float(np.percentile(b, 99)), "max": float(b.max())}
    return out
