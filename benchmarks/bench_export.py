"""The exported controller on this machine: step time over 10^6 steps and the 1 kHz loop's jitter.

Exports CFC with the momentum observer for the paper's robot (case 2's gains), builds it with
make (the compiler of ``$CC``, default cc, -O2), and runs ``rt_loop --steps N`` (steps back to back)
and ``rt_loop --seconds S`` (the 1 kHz loop on clock_nanosleep TIMER_ABSTIME, SCHED_FIFO where
permitted). Baseline of the same run: the control period (1 ms), the budget of one step.
``VGTARM_BENCH_EXPORT_STEPS`` and ``VGTARM_BENCH_EXPORT_SECONDS`` shorten it (default 10^6, 10 s).
"""

from __future__ import annotations

import os
import re
import subprocess
import tempfile
from pathlib import Path

import vgtarm
from vgtarm.export import export_controller

_LINE = re.compile(r"^(jitter|step time)\s+(.*)\((\d+) samples\)")
_FIGURE = re.compile(r"(p50|p99\.99|p99\.9|p99|max)\s+([0-9.]+) us")


def _percentiles(output: str) -> dict[str, dict[str, float]]:
    found: dict[str, dict[str, float]] = {}
    for line in output.splitlines():
        match = _LINE.match(line)
        if match:
            found[match[1]] = {name: float(value) for name, value in _FIGURE.findall(match[2])}
    return found


def run() -> dict[str, dict[str, float]]:
    steps = int(os.environ.get("VGTARM_BENCH_EXPORT_STEPS", "1000000"))
    seconds = float(os.environ.get("VGTARM_BENCH_EXPORT_SECONDS", "10"))
    robot = vgtarm.load_robot()
    with tempfile.TemporaryDirectory(prefix="vgtc-bench-") as scratch:
        folder = export_controller(robot, Path(scratch) / "controller", observer="momentum").folder
        compiler = os.environ.get("CC", "cc")
        subprocess.run(["make", "-s", f"CC={compiler}", "rt_loop"], cwd=folder, check=True, capture_output=True)
        back_to_back = subprocess.run(
            [str(folder / "rt_loop"), "--steps", str(steps)], check=True, capture_output=True, text=True
        ).stdout
        loop = subprocess.run(
            [str(folder / "rt_loop"), "--seconds", str(seconds)], check=True, capture_output=True, text=True
        ).stdout
    scheduling = next((line for line in loop.splitlines() if line.startswith("scheduling")), "")
    timed = _percentiles(back_to_back)["step time"]
    periodic = _percentiles(loop)
    print(f"\n### Exported controller (CFC + momentum observer, 7 joints, {compiler} -O2)\n")
    print(f"{scheduling}\n")
    print("| figure | p50 | p99 | p99.9 | p99.99 | max | baseline (same run) | target |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    rows = [
        (f"step time, {steps:,} steps back to back", timed, "p99.9 <= 10 us, max <= 50 us"),
        (f"step time inside the 1 kHz loop ({seconds:g} s)", periodic["step time"], ""),
        (f"wake-up jitter of the 1 kHz loop ({seconds:g} s)", periodic["jitter"], "measured"),
    ]
    for name, figures, target in rows:
        cells = " | ".join(f"{figures[k]:.2f} us" for k in ("p50", "p99", "p99.9", "p99.99", "max"))
        print(f"| {name} | {cells} | period 1000 us: p99.9 at {figures['p99.9'] / 10:.2f} % of it | {target} |")
    return {"steps": timed, **periodic}
