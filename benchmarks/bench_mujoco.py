"""MuJoCo as the plant: the cost of one control period against our compiled loop, same run.

Case 1 with computed force control over its first second (1,000 periods): our compiled loop
(explicit Euler, one step per period), and MuJoCo stepping the exported model (at least
``MIN_STEPS`` MuJoCo steps per period, see ``vgtarm.mujoco_bridge.plant``) under the NumPy twin
of the controller.
"""

from __future__ import annotations

import time

import vgtarm
from vgtarm.app.cases import case_study, joint_reference
from vgtarm.simulation import JointReference, simulate

from .common import Row, best_time, print_table

SAMPLES = 1001


def run() -> list[Row]:
    try:
        import mujoco  # noqa: F401
    except ImportError:
        print("\n(MuJoCo benchmark skipped: pip install 'vgtarm[mujoco]')")
        return []
    robot = vgtarm.load_robot()
    full = joint_reference(robot, 1)
    ref = JointReference(full.t[:SAMPLES], full.q[:SAMPLES], full.qd[:SAMPLES], full.qdd[:SAMPLES])
    cfc = case_study(1).controller("cfc")
    steps = SAMPLES - 1
    ours = best_time(lambda: simulate(robot, ref, cfc), repeat=3)
    start = time.perf_counter()
    run_mj = simulate(robot, ref, cfc, plant_engine="mujoco")
    mj = time.perf_counter() - start
    duration = float(ref.t[-1] - ref.t[0])
    rows = [
        Row("our compiled loop, case 1 CFC", ours, "period", steps, "MuJoCo plant (same controller)", mj),
        Row("MuJoCo plant, case 1 CFC", mj, "period", steps, "real time", duration),
    ]
    print_table("MuJoCo as the plant (case 1, first second)", rows)
    print(f"max tip error on MuJoCo {run_mj.summary()['max_tip_error_m'] * 1e3:.4f} mm over the first second")
    return rows


if __name__ == "__main__":
    run()
