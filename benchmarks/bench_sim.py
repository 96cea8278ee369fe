"""Closed-loop benchmark: case 1 with computed force control and with the switching method.

Baselines, measured in the same run: the same closed loop in NumPy through the interpreted
model (the project's fallback, a fair stand-in for a Python simulation loop; timed on the first
300 samples and scaled), and the simulated duration itself (real time).
"""

from __future__ import annotations

import time

import vgtarm
from vgtarm.experiment.cases import joint_reference, run_case
from vgtarm.model.compiled import InterpretedBackend, build_functions
from vgtarm.simulation import JointReference

from .common import Row, best_time, print_table


def run() -> list[Row]:
    robot = vgtarm.load_robot()
    reference = joint_reference(robot, 1)
    steps = len(reference.t) - 1
    duration = float(reference.t[-1] - reference.t[0])
    slow = vgtarm.Robot(robot.parameters, InterpretedBackend(build_functions()))
    head = 300
    short = JointReference(
        reference.t[: head + 1], reference.q[: head + 1], reference.qd[: head + 1], reference.qdd[: head + 1]
    )
    numpy_loop = best_time(lambda: run_case(slow, 1, reference=short), repeat=1, min_time=0.0) * steps / head
    cfc = best_time(lambda: run_case(robot, 1, reference=reference), repeat=5)
    rows = [
        Row("case 1, CFC, compiled loop (6,283 steps)", cfc, "step", steps, "real time", duration, ">= 100x real time"),
        Row(
            "case 1, CFC, compiled loop (6,283 steps)", cfc, "step", steps, "NumPy loop (interpreted model)", numpy_loop
        ),
    ]
    start = time.perf_counter()
    scm_result = run_case(robot, 1, controller="scm", reference=reference, scm_variant="paper")
    scm = time.perf_counter() - start
    rows.append(
        Row("case 1, SCM with every GA activation", scm, "step", steps, "real time", duration, "faster than real time")
    )
    activations = scm_result.activations
    if activations:
        per = scm_result.ga_time_s / len(activations)
        rows.append(
            Row(
                f"one GA activation (of {len(activations)}; 50 x 50, horizon 20)",
                per,
                "activation",
                1,
                "real time of one control period",
                reference.dt,
            )
        )
    print_table("Closed loop, case 1 (6.283 s simulated, dt = 1 ms)", rows)
    return rows


if __name__ == "__main__":
    run()
