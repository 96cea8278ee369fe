"""Study benchmark: 200 case-1 CFC runs (whole path, seeds 0..199) on Dask against bare simulate calls.

Baseline, measured in the same run: the same 200 runs as plain ``simulate`` calls in this
process, one after the other, with the reference computed once. The studies include everything a
user waits for: starting the local cluster, loading the model in each worker, the joint
reference per worker, storing every run and writing the tables.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import vgtarm
from vgtarm.app.study_points import check_point, execute_point
from vgtarm.experiment.cases import joint_reference, run_case
from vgtarm.study.runner import run_study
from vgtarm.study.spec import parse_study

from .common import Row, print_table

RUNS = 200


def run() -> list[Row]:
    robot = vgtarm.load_robot()
    reference = joint_reference(robot, 1)
    run_case(robot, 1, reference=reference)  # warm up
    start = time.perf_counter()
    for seed in range(RUNS):
        run_case(robot, 1, reference=reference, seed=seed)
    bare = time.perf_counter() - start
    study = parse_study({"study": {"name": "bench", "case": 1, "seeds": RUNS}, "grid": {"controller": "cfc"}})
    timings: dict[int, float] = {}
    for workers in (1, 2):
        with tempfile.TemporaryDirectory() as folder:
            start = time.perf_counter()
            made = run_study(study, Path(folder), execute_point, check=check_point, workers=workers, progress=False)
            timings[workers] = time.perf_counter() - start
            assert made.executed == RUNS and made.failed == 0
    rows = [
        Row(f"{RUNS} case-1 CFC runs, study on 1 worker", timings[1], "run", RUNS, "bare simulate calls", bare),
        Row(
            f"{RUNS} case-1 CFC runs, study on 2 workers",
            timings[2],
            "run",
            RUNS,
            "bare simulate calls",
            bare,
            "< 30 s in all; overhead < 20 % per run",
        ),
        Row(f"{RUNS} case-1 CFC runs, study on 2 workers", timings[2], "run", RUNS, "study on 1 worker", timings[1]),
    ]
    print_table(f"Studies on Dask ({RUNS} case-1 CFC runs of 6.283 s simulated)", rows)
    print(
        f"\noverhead per run, 1 worker: {(timings[1] - bare) / RUNS * 1e3:.2f} ms"
        f" ({(timings[1] / bare - 1) * 100:.0f} % of a bare run, cluster start-up included)"
    )
    return rows
