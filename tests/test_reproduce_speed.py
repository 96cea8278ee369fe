"""What made ``vgtarm reproduce`` faster changes no number it writes.

- The CSV writer formats all-finite rows with one ``%`` format each and only rows with a NaN field
  by field: the same bytes as the first writer (one format per row, then a regular expression that
  emptied ``nan`` fields), and every number reads back to the same bits.
- Runs and figures made by worker processes (:mod:`vgtarm.app.pool`) are bit for bit the runs made
  in one process; only wall times differ.
- Ctrl-C ends a reproduction with workers at once, with the one line, and leaves no process behind.

No test here measures time: ``python -m benchmarks reproduce`` does.
"""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import numpy as np
import pytest

from tests.test_interrupt import ENDS_WITHIN, _alive_in_group, _assert_interrupted, _Command, warm  # noqa: F401
from vgtarm.app.pool import Inline, Workers
from vgtarm.app.reports.beyond import ENCODER_RESOLUTION, beyond_runs
from vgtarm.app.reports.reproduce import RunSpec, _beyond_run, reproduce
from vgtarm.errors import InputError
from vgtarm.experiment.cases import joint_reference
from vgtarm.simulation.result import GAActivation, _csv
from vgtarm.study.store import TIMING_COLUMNS


def _csv_with_a_regex(columns: list[str], table: np.ndarray) -> str:
    """The first CSV writer: the reference."""
    row_format = ",".join(["%.17g"] * len(columns))
    body = "\n".join(row_format % tuple(row) for row in np.asarray(table, dtype=float).tolist())
    body = re.sub(r"(?m)(?<![^,\n])nan(?![^,\n])", "", body)
    return ",".join(columns) + "\n" + (body + "\n" if len(table) else "")


@pytest.mark.parametrize("shape", [(0, 3), (1, 1), (5, 4), (300, 47)])
def test_csv_is_the_first_writers_text_and_reads_back_bit_for_bit(shape):
    rng = np.random.default_rng(shape[0] * 100 + shape[1])
    specials = np.array([np.nan, -np.nan, np.inf, -np.inf, 0.0, -0.0, 5e-324, -2.2250738585072014e-308, 1e308, 0.1])
    table = rng.standard_normal(shape) * 10.0 ** rng.integers(-30, 30, size=shape)
    mask = rng.random(shape) < 0.15
    table[mask] = rng.choice(specials, size=int(mask.sum()))
    if shape[0] > 10:
        table[3] = np.nan  # a row of only NaN
        table[4] = rng.integers(-5, 5, size=shape[1])  # whole numbers, as the mode column
    columns = [f"c{i}" for i in range(shape[1])]
    text = _csv(columns, table)
    assert text == _csv_with_a_regex(columns, table)
    lines = text.split("\n")
    assert lines[0] == ",".join(columns) and lines[-1] == "" and len(lines) == shape[0] + 2
    back = np.array([[float(f) if f else np.nan for f in line.split(",")] for line in lines[1:-1]]).reshape(shape)
    np.testing.assert_array_equal(np.isnan(back), np.isnan(table))
    same = ~np.isnan(table)
    assert (back[same].view(np.int64) == table[same].view(np.int64)).all(), "the exact bits, signed zeros too"


def _same_folder_but_times(a: Path, b: Path) -> None:
    """Two reproductions hold the same files, the same bytes in every CSV (the GA activations'
    wall times aside) and every figure, and the same summaries but for the times."""
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file())
    wall = list(GAActivation.__dataclass_fields__).index("wall_time_s")
    for name in files:
        if name.name == "timeseries.csv":
            assert (a / name).read_bytes() == (b / name).read_bytes(), name
        elif name.name == "ga_activations.csv":
            rows_a, rows_b = ((x / name).read_text().splitlines() for x in (a, b))
            cut = [[[f for i, f in enumerate(r.split(",")) if i != wall] for r in rows] for rows in (rows_a, rows_b)]
            assert cut[0] == cut[1], name
        elif name.suffix == ".png":  # drawn by a worker or here: the same picture, byte for byte
            assert (a / name).read_bytes() == (b / name).read_bytes(), name
        elif name.name == "summary.json":
            sa, sb = (json.loads((x / name).read_text()) for x in (a, b))
            assert {k: v for k, v in sa.items() if k not in TIMING_COLUMNS} == {
                k: v for k, v in sb.items() if k not in TIMING_COLUMNS
            }
    lines_a, lines_b = ((x / "report.md").read_text().splitlines() for x in (a, b))
    assert [line for line in lines_a if "![" in line] == [line for line in lines_b if "![" in line]


def test_a_reproduction_by_two_workers_is_the_one_made_here(robot, tmp_path):
    specs = [RunSpec(1, "cfc", False, "exact"), RunSpec(1, "scm", False, "exact")]  # SCM: the GA in a worker
    serial = reproduce(robot, tmp_path / "serial", runs=specs, beyond_paper=False, workers=1)
    parallel = reproduce(robot, tmp_path / "parallel", runs=specs, beyond_paper=False, workers=2)
    assert list(serial.results) == list(parallel.results) == specs
    assert parallel.results[specs[1]].activations, "the GA ran"
    _same_folder_but_times(tmp_path / "serial", tmp_path / "parallel")
    with pytest.raises(InputError, match=r"^workers = 0: expected a whole number >= 1 \(processes\)$"):
        reproduce(robot, tmp_path / "none", runs=specs, workers=0)
    assert not (tmp_path / "none").exists()


def test_beyond_runs_made_by_workers_are_the_runs_made_here(robot, tmp_path):
    """The realistic runs build a heavier controller model from the worker's robot; the forced one
    its own external force."""
    reference = joint_reference(robot, 2, duration=0.3)
    chosen = [
        run
        for run in beyond_runs()
        if (run.label == "CFC + observer" and run.realistic) or run.label == "CFC + observer, cutting force only"
    ]
    assert len(chosen) == 2
    options = {"seed": 0, "integrator": "euler", "substeps": 1}
    with Inline(robot) as here:
        made_here = [here.submit(_beyond_run, run, reference, tmp_path / "here", options).result() for run in chosen]
    with Workers(2, robot.parameters) as pool:
        futures = [pool.submit(_beyond_run, run, reference, tmp_path / "workers", options) for run in chosen]
        made_there = [future.result() for future in futures]
    assert made_here[0].metadata["encoder_resolution_m"] == ENCODER_RESOLUTION
    for one, other in zip(made_here, made_there, strict=True):
        for name in ("q", "qd", "effort", "f_ext", "tip_error", "effort_estimate"):
            np.testing.assert_array_equal(getattr(one, name), getattr(other, name), err_msg=name)
    for run in chosen:
        assert (tmp_path / "here" / run.folder / "timeseries.csv").read_bytes() == (
            tmp_path / "workers" / run.folder / "timeseries.csv"
        ).read_bytes()


def test_ctrl_c_ends_a_reproduction_and_its_workers(warm, tmp_path):  # noqa: F811
    out = tmp_path / "results"
    command = _Command(["reproduce", "--out", str(out)], warm)
    took = command.interrupt_when(lambda: command.working() and b"reproduce" in command.err, then=1.5)
    _assert_interrupted(command, took, "reproduce with worker processes")
    deadline = time.monotonic() + ENDS_WITHIN
    while _alive_in_group(command.child.pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert _alive_in_group(command.child.pid) == []
    assert not out.exists()


def test_workers_build_a_stacks_robot_and_make_its_runs_bit_for_bit(tmp_path):
    """A worker builds the robot of the parameters it is given, a stack too (its structure's
    library, not the paper's): a switching-control run of the six-module arm matches the one made here."""
    from functools import partial

    from vgtarm import load_robot
    from vgtarm.experiment.cases import run_case

    six = load_robot(Path(__file__).resolve().parents[1] / "examples" / "six_modules.toml")
    reference = joint_reference(six, 1, duration=0.1)
    here = run_case(six, 1, controller="scm", reference=reference, seed=2, scm_variant="paper")
    with Workers(1, six.parameters) as pool:
        there = pool.submit(
            partial(run_case, controller="scm", reference=reference, seed=2, scm_variant="paper"), 1
        ).result()
    for name in ("q", "effort", "tip_error"):
        np.testing.assert_array_equal(getattr(here, name), getattr(there, name), err_msg=name)
