"""Inverse-kinematics benchmark: the whole case 1 path at 1 ms with the fast solver against the reference.

Baseline, measured in the same run: the per-sample reference solver (SciPy SLSQP, exact
gradients from the compiled model, each sample warm-started from the previous one), which is too
slow to run on all 6,284 samples inside a benchmark. It is timed on ``BLOCKS`` blocks of
``BLOCK`` consecutive samples spread along the path, each block started from the fast solution of
the sample before it (as if the reference had solved it), and its time is scaled to the whole
path. Both runs include the exact rates and the per-sample verification. The worst differences
between the two solutions are measured on the same blocks.

Where the fast solver's time goes (issue 35): the share of one call spent in the compiled model's
evaluations (:meth:`vgtarm.Robot.evaluate`, with its checks and its threads), the median of
``SPLIT_CALLS`` calls; the rest is the solver's NumPy work and Python.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

import vgtarm
from vgtarm import paths
from vgtarm.ik import inverse_kinematics

from .common import Row, best_time, print_table

BLOCKS = 4
BLOCK = 150
#: Calls of the fast solver timed for the split between the model's evaluations and the rest.
SPLIT_CALLS = 15


def _model_split(robot: vgtarm.Robot, solve: Callable[[], object]) -> tuple[float, float, int, int]:
    """Median seconds of ``solve()`` and of the model evaluations in it, evaluations and samples per call."""
    evaluate = robot.evaluate
    spent, counts = [0.0], [0, 0]

    def timed(name: str, inputs: Any, n: int) -> dict[str, np.ndarray]:
        begin = time.perf_counter()
        try:
            return evaluate(name, inputs, n)
        finally:
            spent[0] += time.perf_counter() - begin
            counts[0] += 1
            counts[1] += n

    robot.evaluate = timed  # type: ignore[method-assign]
    try:
        totals, models = [], []
        for _ in range(SPLIT_CALLS):
            spent[0], counts[:] = 0.0, [0, 0]
            begin = time.perf_counter()
            solve()
            totals.append(time.perf_counter() - begin)
            models.append(spent[0])
    finally:
        del robot.evaluate
    return float(np.median(totals)), float(np.median(models)), counts[0], counts[1]


def _reference_on_blocks(
    robot: vgtarm.Robot, path: paths.TipPath, fast_q: np.ndarray
) -> tuple[float, float, float, int]:
    """Seconds per sample of the reference, worst |Phi_fast - Phi_ref|, worst tip residual, samples timed."""
    n = len(path)
    starts = np.linspace(1, n - BLOCK - 1, BLOCKS).astype(int)
    seconds, dphi, residual, count = 0.0, 0.0, 0.0, 0
    fast = inverse_kinematics(robot, path)
    for s in starts:
        block = paths.TipPath(
            "block",
            path.t[s : s + BLOCK],
            path.position[s : s + BLOCK],
            path.velocity[s : s + BLOCK],
            path.acceleration[s : s + BLOCK],
        )
        ref = inverse_kinematics(robot, block, solver="reference", initial_guess=fast_q[s - 1])
        seconds += ref.wall_time_s
        count += BLOCK
        dphi = max(dphi, float(np.abs(ref.samples.phi - fast.samples.phi[s : s + BLOCK]).max()))
        residual = max(residual, float(ref.samples.residual.max()))
    return seconds / count, dphi, residual, count


def run() -> list[Row]:
    robot = vgtarm.load_robot()
    path = paths.case1(dt=1e-3)
    n = len(path)
    fast = inverse_kinematics(robot, path)
    fast_time = best_time(lambda: inverse_kinematics(robot, path), repeat=7, min_time=0.3)
    per_sample, dphi, ref_residual, count = _reference_on_blocks(robot, path, fast.q)
    effort = inverse_kinematics(robot, path, criterion="effort")
    effort_time = best_time(lambda: inverse_kinematics(robot, path, criterion="effort"), repeat=7, min_time=0.3)
    rows = [
        Row(
            "IK case 1 at 1 ms, fast solver + exact rates",
            fast_time,
            "sample",
            n,
            f"SLSQP reference per sample (timed on {count} samples, scaled)",
            per_sample * n,
            "whole path <= 0.2 s, >= 100x",
        ),
        Row(
            "IK case 1 at 1 ms, effort criterion, fast solver + exact rates",
            effort_time,
            "sample",
            n,
            "the joint-limit criterion (eq. 12), same solver, same run",
            fast_time,
            "whole path < 0.1 s",
        ),
    ]
    print_table(f"Inverse kinematics (case 1, {n:,} samples)", rows)
    print(
        f"\nfast: whole path {fast_time * 1e3:.1f} ms, worst tip residual {fast.samples.residual.max():.2e} m, "
        f"largest Phi {fast.samples.phi.max():.6f}, {np.count_nonzero(fast.samples.iterations == 0):,} samples "
        f"needed no Newton step; reference: worst tip residual {ref_residual:.2e} m; "
        f"worst |Phi_fast - Phi_ref| = {dphi:.2e}"
    )
    print(
        f"effort criterion: whole path {effort_time * 1e3:.1f} ms ({effort_time / fast_time:.2f}x eq. 12), "
        f"{effort.message}, {np.count_nonzero(effort.samples.iterations == 0):,} samples needed no Newton step"
    )
    for label, keywords in (("eq. 12", {}), ("effort criterion", {"criterion": "effort"})):
        total, model, calls, samples = _model_split(robot, lambda k=keywords: inverse_kinematics(robot, path, **k))
        print(
            f"where the time goes ({label}, median of {SPLIT_CALLS} calls): {total * 1e3:.1f} ms, of which "
            f"{model * 1e3:.1f} ms ({model / total:.0%}) in {calls} model evaluations of {samples:,} samples "
            f"and {(total - model) * 1e3:.1f} ms in the solver's NumPy and Python"
        )
    return rows


if __name__ == "__main__":
    run()
