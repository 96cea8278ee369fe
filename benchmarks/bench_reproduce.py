"""``vgtarm reproduce`` benchmark: the whole command, and its phases one by one.

The whole command is timed as a user starts it (a new ``vgtarm reproduce`` process, start-up
included), with its default worker processes, against ``--workers 1`` (everything in one process)
run just before. The phases are timed here, one after the other, each against the way it was done
before, measured in the same run:

- writing the runs' CSV files: one ``%`` format per row, NaN rows field by field, against one
  format per row followed by a regular expression that empties the ``nan`` fields;
- the page's min/max decimation (reshaped buckets, ``reduceat``) against a loop over the buckets;
- the page's Plotly figures written as plain dicts, against the same figures through Plotly's
  per-property validation (``plotly.io.to_html`` of ``go.Figure``);
- the figures (matplotlib), with the GA spans of the effort plots as one collection.
"""

from __future__ import annotations

import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import vgtarm
from vgtarm.app.pool import default_workers
from vgtarm.app.reports import html as html_report
from vgtarm.app.reports.beyond import beyond_figure, run_beyond
from vgtarm.app.reports.reproduce import draw_figure, figure_plan, paper_runs
from vgtarm.experiment.cases import joint_reference, run_case
from vgtarm.simulation.result import _csv

from .common import Row, print_table

#: The command, as installed beside this interpreter.
VGTARM = Path(sys.executable).parent / "vgtarm"


def _csv_with_a_regex(columns: list[str], table: np.ndarray) -> str:
    row_format = ",".join(["%.17g"] * len(columns))
    body = "\n".join(row_format % tuple(row) for row in np.asarray(table, dtype=float).tolist())
    body = re.sub(r"(?m)(?<![^,\n])nan(?![^,\n])", "", body)
    return ",".join(columns) + "\n" + (body + "\n" if len(table) else "")


def _decimate_in_a_loop(y: np.ndarray, max_points: int) -> np.ndarray:
    n = len(y)
    if n <= max_points:
        return np.arange(n)
    edges = np.linspace(1, n - 1, (max_points - 2) // 2 + 1).astype(np.int64)
    keep = [0, n - 1]
    finite = np.where(np.isfinite(y), y, np.nan)
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        chunk = finite[lo:hi]
        if hi > lo and not np.isnan(chunk).all():
            keep += [lo + int(np.nanargmin(chunk)), lo + int(np.nanargmax(chunk))]
    return np.unique(np.array(keep, dtype=np.int64))


def _command(out: Path, *options: str) -> float:
    start = time.perf_counter()
    subprocess.run([str(VGTARM), "reproduce", "--out", str(out), "-q", *options], check=True, capture_output=True)
    return time.perf_counter() - start


def _clock(f) -> tuple[float, object]:  # type: ignore[no-untyped-def]
    start = time.perf_counter()
    value = f()
    return time.perf_counter() - start, value


def run() -> list[Row]:
    workers = default_workers()
    with tempfile.TemporaryDirectory() as folder:
        serial = _command(Path(folder) / "serial", "--workers", "1")
        parallel = _command(Path(folder) / "parallel")
    robot = vgtarm.load_robot()
    phases: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        specs = paper_runs()
        references = {}
        start = time.perf_counter()
        results = {}
        for spec in specs:
            key = (spec.case, spec.rates)
            if key not in references:
                references[key] = joint_reference(robot, spec.case, rates=spec.rates)
            results[spec] = run_case(
                robot, spec.case, controller=spec.controller, external_force=spec.external_force,
                rates=spec.rates, reference=references[key], scm_variant="paper",
            )  # fmt: skip
        phases["the paper's 12 runs"] = time.perf_counter() - start
        phases["the 14 runs beyond the paper (saved)"], extra = _clock(
            lambda: run_beyond(robot, references[(2, "exact")], folder, seed=0, integrator="euler", substeps=1)
        )
        tables = [r._table() for r in results.values()]
        phases["CSV of the paper's runs"], _ = _clock(lambda: [_csv(c, t) for c, t in tables])
        before_csv, _ = _clock(lambda: [_csv_with_a_regex(c, t) for c, t in tables])
        plan = figure_plan(specs)
        phases["figures (12 + 1)"], _ = _clock(
            lambda: ([draw_figure(p, results, folder) for p in plan], beyond_figure(extra, folder))  # type: ignore[arg-type]
        )
        runs = html_report.runs_from_reproduction(results)
        phases["report.html"], _ = _clock(lambda: html_report.write_html_report(robot, runs, folder))
    series = [(r.t, y) for r in results.values() for y in (r.tip_error, *r.effort.T)]
    decimated, _ = _clock(lambda: [html_report.decimate_min_max(t, y) for t, y in series])
    looped, _ = _clock(lambda: [_decimate_in_a_loop(y, html_report.MAX_POINTS) for _, y in series])
    figures = html_report.page_figures(robot, runs)
    import plotly.graph_objects as go
    import plotly.io as pio

    as_dicts, _ = _clock(lambda: [pio.to_html(f, validate=False, full_html=False) for _, _, f in figures])
    validated, _ = _clock(lambda: [pio.to_html(go.Figure(f), full_html=False) for _, _, f in figures])
    rows = [
        Row(
            f"vgtarm reproduce, {workers} worker processes",
            parallel,
            "reproduction",
            1,
            "--workers 1",
            serial,
            "< 25 s (aim: < 20 s idle)",
        ),
        Row("CSV of the 12 paper runs", phases["CSV of the paper's runs"], "run", 12, "regex on NaN", before_csv),
        Row(f"min/max decimation of {len(series)} series", decimated, "series", len(series), "loop", looped),
        Row("report.html's Plotly figures to HTML", as_dicts, "figure", len(figures), "validated", validated),
    ]
    print_table("vgtarm reproduce (every run, figures and report)", rows)
    print("\nphases, one after the other in this process:\n")
    print("| phase | time |\n| --- | --- |")
    for phase, seconds in phases.items():
        print(f"| {phase} | {seconds:.2f} s |")
    return rows
