"""MuJoCo as the plant: the cost of one control period against our compiled loop, same run.

Case 1 with computed force control over its first second (1,000 periods), one step per period:
our compiled loop (explicit Euler, the default), and MuJoCo stepping the exported model under the
NumPy twin of the controller with the same explicit Euler (accelerations from MuJoCo, the step
taken by ``vgtarm.mujoco_bridge.plant``), with MuJoCo's semi-implicit Euler and with its RK4.
"""

from __future__ import annotations

import time

import vgtarm
from vgtarm.experiment.cases import case_study, joint_reference
from vgtarm.simulation import JointReference, simulate

from .common import Row, best_time, print_table

SAMPLES = 1001


def run() -> list[Row]:
    try:
        import mujoco  # noqa: F401
    except ImportError:
        print("\n(MuJoCo benchmark skipped: pip install 'vgtarm[mujoco]')")
        return []
    from vgtarm import mujoco_bridge  # noqa: F401  (registers the MuJoCo plant)

    robot = vgtarm.load_robot()
    full = joint_reference(robot, 1)
    ref = JointReference(full.t[:SAMPLES], full.q[:SAMPLES], full.qd[:SAMPLES], full.qdd[:SAMPLES])
    cfc = case_study(1).controller("cfc")
    steps = SAMPLES - 1
    ours = best_time(lambda: simulate(robot, ref, cfc), repeat=3)
    timed = {}
    for integrator in ("euler", "semi_implicit_euler", "rk4"):
        start = time.perf_counter()
        run_mj = simulate(robot, ref, cfc, integrator=integrator, plant_engine="mujoco")
        timed[integrator] = (time.perf_counter() - start, run_mj.summary()["max_tip_error_m"])
    duration = float(ref.t[-1] - ref.t[0])
    rows = [
        Row("our compiled loop, case 1 CFC", ours, "period", steps, "MuJoCo plant (explicit Euler)", timed["euler"][0]),
        Row("MuJoCo plant, explicit Euler x1", timed["euler"][0], "period", steps, "real time", duration),
        Row(
            "MuJoCo plant, semi-implicit Euler x1",
            timed["semi_implicit_euler"][0],
            "period",
            steps,
            "real time",
            duration,
        ),
        Row("MuJoCo plant, RK4 x1", timed["rk4"][0], "period", steps, "real time", duration),
    ]
    print_table("MuJoCo as the plant (case 1, first second)", rows)
    for integrator, (_, error) in timed.items():
        print(f"max tip error on MuJoCo ({integrator}) {error * 1e3:.4f} mm over the first second")
    return rows


if __name__ == "__main__":
    run()
