"""The exported controller on this machine: step time over 10^6 steps and the 1 kHz loop's jitter.

Exports CFC with the momentum observer for the paper's robot (case 2's gains), builds it with
make (the compiler of ``$CC``, default cc, -O2), and runs ``rt_loop --steps N`` (steps back to back)
and ``rt_loop --seconds S`` (the 1 kHz loop on clock_nanosleep TIMER_ABSTIME, SCHED_FIFO where
permitted). Baseline of the same run: the control period (1 ms), the budget of one step. Then the
same with the Kalman state estimate (1 um encoders, a controller model 10 % heavy, CFC + observer +
Kalman filter: one more generated function a step, the forward dynamics), back to back against
the first export's steps measured in the same run. The baseline of the steps' tails: the machine
alone (``csrc/machine_noise.c``: a fixed chain of operations as long as a step at the median,
timed the same way, between two runs of the steps), so a tail the machine has too is not the
controller's.
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
from vgtarm.simulation import Scenario

_NOISE = Path(__file__).parent / "csrc" / "machine_noise.c"
_LINE = re.compile(r"^(jitter|step time)\s+(.*)\((\d+) samples\)")
_FIGURE = re.compile(r"(p50|p99\.99|p99\.9|p99|max)\s+([0-9.]+) us")


def _percentiles(output: str) -> dict[str, dict[str, float]]:
    found: dict[str, dict[str, float]] = {}
    for line in output.splitlines():
        match = _LINE.match(line)
        if match:
            found[match[1]] = {name: float(value) for name, value in _FIGURE.findall(match[2])}
    return found


def _machine_noise(scratch: Path, compiler: str, median_us: float, steps: int) -> dict[str, float]:
    """The baseline of the step's tails: ``csrc/machine_noise.c``, a computation that never changes,
    calibrated to the step's median and timed as ``rt_loop --steps`` times the steps."""
    program = scratch / "machine_noise"
    subprocess.run(
        [compiler, "-std=c99", "-O2", "-o", str(program), str(_NOISE), "-lm"], check=True, capture_output=True
    )
    out = subprocess.run([str(program), f"{median_us:.4f}", str(steps)], check=True, capture_output=True, text=True)
    return _percentiles(out.stdout)["step time"]


def run() -> dict[str, dict[str, float]]:
    steps = int(os.environ.get("VGTARM_BENCH_EXPORT_STEPS", "1000000"))
    seconds = float(os.environ.get("VGTARM_BENCH_EXPORT_SECONDS", "10"))
    robot = vgtarm.load_robot()
    compiler = os.environ.get("CC", "cc")
    with tempfile.TemporaryDirectory(prefix="vgtc-bench-") as scratch:
        folder = export_controller(robot, Path(scratch) / "controller", scenario=Scenario(observer="momentum")).folder
        subprocess.run(["make", "-s", f"CC={compiler}", "rt_loop"], cwd=folder, check=True, capture_output=True)

        def rt_loop(*args: str) -> str:
            return subprocess.run([str(folder / "rt_loop"), *args], check=True, capture_output=True, text=True).stdout

        timed = _percentiles(rt_loop("--steps", str(steps)))["step time"]
        noise = _machine_noise(Path(scratch), compiler, timed["p50"], steps)
        again = _percentiles(rt_loop("--steps", str(steps)))["step time"]
        fed = _percentiles(rt_loop("--steps", str(steps), "--feedforward"))["step time"]
        loop = rt_loop("--seconds", str(seconds))
        kalman = _kalman(robot, Path(scratch), compiler, steps, seconds, folder)
        kalman["baseline loop"] = _percentiles(loop)["step time"]
    scheduling = next((line for line in loop.splitlines() if line.startswith("scheduling")), "")
    periodic = _percentiles(loop)
    print(f"\n### Exported controller (CFC + momentum observer, 7 joints, {compiler} -O2)\n")
    print(f"{scheduling}\n")
    print("| figure | p50 | p99 | p99.9 | p99.99 | max | baseline (same run) | target |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    rows = [
        (f"step time, {steps:,} steps back to back", timed, "p99.9 <= 10 us, max <= 50 us"),
        ("the machine alone: a fixed chain of operations, its median matched, timed the same way", noise, ""),
        ("step time, back to back again (after the machine's)", again, ""),
        ("with the tool-force feedforward (vgtc_step_feedforward), back to back", fed, ""),
        (f"step time inside the 1 kHz loop ({seconds:g} s)", periodic["step time"], ""),
        (f"wake-up jitter of the 1 kHz loop ({seconds:g} s)", periodic["jitter"], "measured"),
    ]
    for name, figures, target in rows:
        cells = " | ".join(f"{figures[k]:.2f} us" for k in ("p50", "p99", "p99.9", "p99.99", "max"))
        print(f"| {name} | {cells} | period 1000 us: p99.9 at {figures['p99.9'] / 10:.2f} % of it | {target} |")
    _print_kalman(kalman, steps, seconds, compiler)
    return {"steps": timed, "machine": noise, "feedforward": fed, **periodic, **kalman}


def _kalman(
    robot: vgtarm.Robot, scratch: Path, compiler: str, steps: int, seconds: float, baseline: Path
) -> dict[str, dict[str, float]]:
    """The export with the Kalman state estimate, its steps back to back alternating with the
    baseline export's (the same run, so the same load), and in the 1 kHz loop."""
    folder = export_controller(
        robot,
        scratch / "kalman",
        scenario=Scenario(
            observer="momentum",
            encoder_resolution=1e-6,
            estimator="kalman",
            controller_model=robot.parameters.scaled(mass=1.1),
        ),
    ).folder
    subprocess.run(["make", "-s", f"CC={compiler}", "rt_loop"], cwd=folder, check=True, capture_output=True)
    figures: dict[str, dict[str, float]] = {}
    for name, where in (("kalman steps", folder), ("baseline steps", baseline), ("kalman steps 2", folder)):
        output = subprocess.run(
            [str(where / "rt_loop"), "--steps", str(steps)], check=True, capture_output=True, text=True
        ).stdout
        figures[name] = _percentiles(output)["step time"]
    loop = subprocess.run(
        [str(folder / "rt_loop"), "--seconds", str(seconds)], check=True, capture_output=True, text=True
    ).stdout
    figures["kalman loop"] = _percentiles(loop)["step time"]
    return figures


def _print_kalman(figures: dict[str, dict[str, float]], steps: int, seconds: float, compiler: str) -> None:
    print(
        f"\n### Exported controller with the Kalman state estimate (CFC + observer + Kalman filter, 1 um"
        f" encoders, model mass 1.1, {compiler} -O2)\n"
    )
    print("| figure | p50 | p99 | p99.9 | p99.99 | max | baseline (same run) |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for name, label, base in (
        ("kalman steps", f"step time, {steps:,} steps back to back", "baseline steps"),
        ("kalman steps 2", "the same, again after the baseline", "baseline steps"),
        ("baseline steps", "baseline: CFC + observer (differences), back to back", "baseline steps"),
        ("kalman loop", f"step time inside the 1 kHz loop ({seconds:g} s)", "baseline loop"),
        ("baseline loop", "baseline: CFC + observer in the 1 kHz loop (above)", "baseline loop"),
    ):
        cells = " | ".join(f"{figures[name][k]:.2f} us" for k in ("p50", "p99", "p99.9", "p99.99", "max"))
        ratio = figures[name]["p50"] / figures[base]["p50"]
        print(f"| {label} | {cells} | p50 {ratio:.2f}x the baseline's |")
