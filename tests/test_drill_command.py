"""``vgtarm drill`` (:mod:`vgtarm.app.cli.drill`): the drilling loop of :func:`vgtarm.drilling.drilling_run`
from the command line, its folder, its measures and its refusals."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from vgtarm.app.cli.command import main
from vgtarm.drilling import SERIES

FEMUR = Path(__file__).resolve().parent.parent / "examples" / "bones" / "femur_diaphysis.toml"


def test_the_femur_is_drilled_through_and_the_folder_holds_the_run(tmp_path, capsys):
    """The femur at the defaults: the run ends, breakthrough is detected after the true crossing and
    the drill stops within the protrusion target; the series, events and summary agree."""
    out = tmp_path / "run"
    assert main(["drill", "--bone", str(FEMUR), "--out", str(out), "-q"]) == 0
    printed = capsys.readouterr().out
    assert "protrusion" in printed and "layer 1" in printed
    series = np.loadtxt(out / "timeseries.csv", delimiter=",", skiprows=1)
    assert (out / "timeseries.csv").read_text().splitlines()[0] == ",".join(SERIES)
    summary = json.loads((out / "summary.json").read_text())
    events = (out / "events.csv").read_text().splitlines()
    assert events[0] == "t,kind,layer" and any(",breakthrough," in e for e in events)
    depth = series[:, SERIES.index("depth")]
    assert summary["protrusion"] == pytest.approx(depth.max() - 14e-3, abs=1e-12)
    assert 0.0 < summary["protrusion"] <= summary["targets"]["protrusion"]
    assert summary["detection_delay"] > 0 and summary["false_detections"] == 0
    assert (out / "drilling.png").stat().st_size > 0


def test_a_bad_bone_file_is_refused_in_one_line_and_nothing_is_written(tmp_path, capsys):
    bone = tmp_path / "bone.toml"
    bone.write_text(FEMUR.read_text().replace("\nthickness = 4.0e-3", "\nthickness = -4.0e-3", 1))
    assert "thickness = -4.0e-3" in bone.read_text()
    out = tmp_path / "run"
    assert main(["drill", "--bone", str(bone), "--out", str(out)]) != 0
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and "thickness" in error[0]
    assert not out.exists()


def test_a_bone_whose_cap_breaks_out_is_caught_within_the_target(tmp_path, capsys):
    """The femur with the far cortex's cap breaking out: the command says when, the detection comes
    within the 20 ms target of the breakout, and the apex never reaches the far surface."""
    out = tmp_path / "run"
    cap = FEMUR.with_name("femur_diaphysis_cap.toml")
    assert main(["drill", "--bone", str(cap), "--out", str(out), "-q"]) == 0
    assert "cap        broke out at" in capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert summary["breakthrough_true_time"] == summary["cap_breakout_time"]
    assert 0.0 < summary["detection_delay"] <= summary["targets"]["detection_delay"]
    assert summary["protrusion"] < 0.0 and summary["false_detections"] == 0
