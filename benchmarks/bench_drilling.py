"""Force-controlled drilling: the compiled loop against the NumPy loop it is held to, on the same
run in the same process (docs/drilling_control.md), and the exported controller's period.

The hardest case the commands run: the femur file drilled through in admittance (the default)
and explicit, 1 um encoders, the model 10 % heavy, the observer fed back: 16.5 s of drilling, 16,500
control periods of four plant steps each. Prints a Markdown table: median wall time of each loop
(``REPEATS`` runs of the compiled one, one of NumPy's), the speed-up and the ratio to real time.

Run: ``python -m benchmarks drilling``.
"""

from __future__ import annotations

import time

import numpy as np

import vgtarm
from vgtarm.drilling import FEMUR

REPEATS = 5


def _timed(run, repeats):
    times, out = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        out = run()
        times.append(time.perf_counter() - start)
    return float(np.median(times)), out


def run() -> None:
    robot = vgtarm.load_robot()
    bone = vgtarm.load_bone(FEMUR)
    print("\n### Drilling the femur: the compiled loop against the NumPy loop (same run, same process)\n")
    print("| force loop | simulated (s) | NumPy loop (s) | compiled loop (s) | speed-up | compiled, x real time |")
    print("| --- | --- | --- | --- | --- | --- |")
    for mode in ("admittance", "explicit"):
        settings = vgtarm.DrillingSettings(mode=mode)
        fast, result = _timed(lambda s=settings: vgtarm.drilling_run(robot, bone, s, engine="compiled"), REPEATS)
        slow, _ = _timed(lambda s=settings: vgtarm.drilling_run(robot, bone, s, engine="numpy"), 1)
        simulated = float(result.column("t")[-1])
        print(
            f"| {mode} | {simulated:.1f} | {slow:.2f} | {fast:.3f} | {slow / fast:.0f} x | {simulated / fast:.0f} x |"
        )
