"""``vgtarm simulate --path FILE --kp --kv`` (issue 27, item 3): your path, your gains, kept in summary.json."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vgtarm import paths
from vgtarm.app.cli.command import main
from vgtarm.simulation import Scenario, SimulationResult

DURATION = 0.3


@pytest.fixture(scope="module")
def case1_file(tmp_path_factory):
    """The first 0.3 s of case 1 sampled every millisecond, as a path file."""
    path = paths.case1(1e-3)
    n = int(round(DURATION / 1e-3)) + 1
    file = tmp_path_factory.mktemp("path") / "start.csv"
    rows = np.column_stack([path.t[:n], path.position[:n]])
    np.savetxt(file, rows, delimiter=",", header="t,x,y,z", comments="", fmt="%.17g")
    return file


def _summary(folder):
    return json.loads((folder / "summary.json").read_text())


def test_a_path_file_tracks_as_the_same_case(tmp_path, case1_file, capsys):
    """The path file holds case 1's samples; its spline differs from the analytic path by far less
    than the tracking error, so the run equals ``--case 1 --duration 0.3`` within 1e-9 m."""
    own, case = tmp_path / "own", tmp_path / "case"
    assert main(["simulate", "--path", str(case1_file), "--kp", "5000", "--kv", "300", "-q", "--out", str(own)]) == 0
    assert main(["simulate", "--case", "1", "--duration", str(DURATION), "-q", "--out", str(case)]) == 0
    a, b = SimulationResult.load(own), SimulationResult.load(case)
    assert a.t.shape == b.t.shape
    np.testing.assert_allclose(a.q, b.q, atol=1e-9, rtol=0)
    np.testing.assert_allclose(a.tip_error, b.tip_error, atol=1e-9, rtol=0)
    assert _summary(own)["max_tip_error_m"] < 1e-3  # it tracks the path
    assert "start.csv" in capsys.readouterr().out


def test_the_summary_keeps_what_repeats_the_run(tmp_path, case1_file):
    out = tmp_path / "run"
    kv = "300,300,300,300,300,300,310"
    assert main(["simulate", "--path", str(case1_file), "--kp", "6000", "--kv", kv, "-q", "--out", str(out)]) == 0
    summary = _summary(out)
    assert summary["path"] == "start" and summary["path_file"] == str(case1_file)
    assert summary["kp"] == [6000.0] * 7 and summary["kv"] == [float(v) for v in kv.split(",")]
    assert "case" not in summary
    Scenario.from_record(summary["scenario"])  # the run's scenario, restorable
    again = tmp_path / "again"
    args = ["--kp", ",".join(map(repr, summary["kp"])), "--kv", ",".join(map(repr, summary["kv"]))]
    assert main(["simulate", "--path", summary["path_file"], *args, "-q", "--out", str(again)]) == 0
    np.testing.assert_array_equal(SimulationResult.load(again).q, SimulationResult.load(out).q)


def test_gains_on_a_case_are_recorded_and_change_the_run(tmp_path):
    out = tmp_path / "run"
    assert main(["simulate", "--case", "1", "--duration", "0.05", "--kp", "8000", "-q", "--out", str(out)]) == 0
    summary = _summary(out)
    assert summary["kp"] == [8000.0] * 7 and summary["kv"] == [300.0] * 7 and summary["case"] == 1
    assert summary["scenario"] is not None


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--case", "1", "--kp", "5000,1"], ["--kp", "5000,1", "7 numbers", "s1 v1 p1 s2 v2 p2 psi3"]),
        (["--case", "1", "--kv", "-3"], ["--kv", "-3", "> 0"]),
        (["--case", "1", "--kv", "nan"], ["--kv", "nan", "finite"]),
        (["--case", "1", "--kp", "1e4,x,1,1,1,1,1"], ["--kp", "1e4,x", "numbers"]),
        (["--case", "1", "--path", "{file}"], ["exactly one of --case 1|2 and --path FILE"]),
        ([], ["exactly one of --case 1|2 and --path FILE"]),
        (["--path", "{missing}"], ["path file", "missing.csv"]),
        (["--path", "{one_row}"], ["need at least 2 data rows"]),
        (["--case", "1", "--controller", "scm", "--kp", "4000"], ["--kp '4000'", "--controller scm", "genes"]),
    ],
)
def test_bad_values_are_refused_in_one_line_before_any_output(tmp_path, case1_file, capsys, args, words):
    one_row = tmp_path / "one.csv"
    one_row.write_text("t,x,y,z\n0,0,0,0.66\n")
    names = {"file": str(case1_file), "missing": str(tmp_path / "missing.csv"), "one_row": str(one_row)}
    out = tmp_path / "out"
    assert main(["simulate", *(a.format(**names) for a in args), "-q", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("vgtarm: error: ") and err.count("\n") == 1, err
    for word in words:
        assert word in err
    assert not out.exists()
