"""Model benchmark: batch forward kinematics and dynamics through the compiled backend.

Baselines, measured in the same run: the same CasADi functions called one configuration at a
time from Python (the way a naive user would), and CasADi's interpreter on the same batch.
"""

from __future__ import annotations

import numpy as np

import vgtarm
from vgtarm.model.compiled import InterpretedBackend, build_functions

from .common import Row, best_time, print_table


def run() -> list[Row]:
    robot = vgtarm.load_robot()
    interpreted = vgtarm.Robot(robot.parameters, InterpretedBackend(build_functions()))
    rng = np.random.default_rng(0)
    p = robot.parameters
    n = 100_000
    q = p.home + rng.uniform(-0.02, 0.02, size=(n, 7))
    qd = rng.normal(scale=0.1, size=(n, 7))
    F = rng.normal(scale=50.0, size=(n, 7))
    small = 2_000
    fk_function = interpreted.backend.functions["fk"]
    p_vec = robot.parameter_vector

    def per_call_fk() -> None:
        for k in range(small):
            fk_function(q[k], p_vec)

    rows = []
    fk_batch = best_time(lambda: robot.forward_kinematics(q))
    rows.append(
        Row(
            "forward kinematics, compiled batch",
            fk_batch,
            "config",
            n,
            "CasADi per-call loop",
            best_time(per_call_fk, repeat=3) * n / small,
            ">= 1,000,000 config/s",
        )
    )
    rows.append(
        Row(
            "forward kinematics, compiled batch",
            fk_batch,
            "config",
            n,
            "CasADi interpreter batch",
            best_time(lambda: interpreted.forward_kinematics(q[:small]), repeat=3) * n / small,
        )
    )
    for name, call, icall, target in [
        ("mass matrix M", lambda: robot.mass_matrix(q), lambda: interpreted.mass_matrix(q[:small]), ""),
        ("bias forces C", lambda: robot.bias_forces(q, qd), lambda: interpreted.bias_forces(q[:small], qd[:small]), ""),
        (
            "forward dynamics qdd",
            lambda: robot.forward_dynamics(q, qd, F),
            lambda: interpreted.forward_dynamics(q[:small], qd[:small], F[:small]),
            "<= 5 us per evaluation",
        ),
    ]:
        rows.append(
            Row(
                f"{name}, compiled batch",
                best_time(call),
                "eval",
                n,
                "CasADi interpreter batch",
                best_time(icall, repeat=3) * n / small,
                target,
            )
        )
    print_table("Model (batch of 100,000 configurations)", rows)
    return rows


if __name__ == "__main__":
    run()
