"""Run every benchmark and print Markdown tables (paste them into docs/benchmarks.md).

``python -m benchmarks`` runs every group but ``stacks``, which compiles ten libraries from cold
(about half an hour on two cores): name it, ``python -m benchmarks stacks``; nor ``pathwide``, a
measurement of minutes (the path-wide effort criterion of issue 22, ``docs/control.md``).
"""

from __future__ import annotations

import sys
from types import SimpleNamespace
from typing import Any

from vgtarm._entry import single_threaded_blas

single_threaded_blas()  # as the vgtarm command does, before NumPy is imported

from . import (  # noqa: E402
    bench_calibration,
    bench_drilling,
    bench_export,
    bench_export_ga,
    bench_footprint,
    bench_ga,
    bench_ik,
    bench_model,
    bench_mujoco,
    bench_path_wide,
    bench_recursive,
    bench_reproduce,
    bench_retime,
    bench_sim,
    bench_single,
    bench_stacks,
    bench_study,
    bench_threads,
    bench_tool_tasks,
)
from .common import machine  # noqa: E402

MODULES: dict[str, Any] = {
    "model": bench_model,
    "sim": bench_sim,
    "ga": bench_ga,
    "ik": bench_ik,
    "study": bench_study,
    "mujoco": bench_mujoco,
    "reproduce": bench_reproduce,
    "stacks": bench_stacks,
    "recursive": bench_recursive,
    # the control figures of the recursive model alone (IK and CFC of case 1; also run by "recursive")
    "recursive-control": SimpleNamespace(run=bench_recursive.control_figures),
    "export": bench_export,
    "export-ga": bench_export_ga,
    "footprint": bench_footprint,
    "pathwide": bench_path_wide,
    "threads": bench_threads,
    "single": bench_single,
    "tools": bench_tool_tasks,
    "retime": bench_retime,
    "calibration": bench_calibration,
    "drilling": bench_drilling,
}
#: Groups run when none is named (``stacks`` is long: it compiles ten libraries from cold).
DEFAULT = [name for name in MODULES if name not in ("stacks", "pathwide", "recursive-control")]


def main(argv: list[str]) -> None:
    chosen = argv or DEFAULT
    unknown = [name for name in chosen if name not in MODULES]
    if unknown:
        raise SystemExit(f"unknown benchmark {unknown[0]!r}; choose from {sorted(MODULES)}")
    print(f"machine: {machine()}")
    for name in chosen:
        MODULES[name].run()


if __name__ == "__main__":
    main(sys.argv[1:])
