"""The drilling section of ``vgtarm reproduce`` (beyond the paper): its runs and study are written
under ``beyond/``, its numbers are those of the runs it saved, its figures exist; the bone file the
package ships is the example's."""

from __future__ import annotations

import csv
import json
from pathlib import Path

from vgtarm.app.reports.drilling_section import CAP_RUN, FOLDER, drilling_available, drilling_section
from vgtarm.drilling import FEMUR, FEMUR_CAP

ROOT = Path(__file__).resolve().parents[1]


def test_the_shipped_femurs_are_the_examples():
    assert FEMUR.read_bytes() == (ROOT / "examples" / "bones" / "femur_diaphysis.toml").read_bytes()
    assert FEMUR_CAP.read_bytes() == (ROOT / "examples" / "bones" / "femur_diaphysis_cap.toml").read_bytes()


def test_the_section_writes_its_runs_and_reports_them(robot, tmp_path):
    assert drilling_available(robot)
    lines = drilling_section(robot, tmp_path, seeds=3)
    text = "\n".join(lines)
    for mode in ("admittance", "explicit"):
        run = tmp_path / FOLDER.format(name=mode)
        summary = json.loads((run / "summary.json").read_text())
        series = list(csv.reader((run / "timeseries.csv").open()))
        assert series[0][:3] == ["t", "depth", "feed"] and len(series) > 1000
        assert (run / "events.csv").read_text().splitlines()[-1].split(",")[1] == "breakthrough"
        row = next(line for line in lines if line.startswith(f"| {mode} |"))
        assert f"| {1e3 * summary['protrusion']:.3f} |" in row
        assert (tmp_path / f"drilling_{mode}.png").stat().st_size > 10_000
    cap = json.loads((tmp_path / FOLDER.format(name=CAP_RUN) / "summary.json").read_text())
    assert 0.0 < cap["detection_delay"] <= 0.020 and cap["protrusion"] < 0.0
    assert "| admittance, the cap breaking out |" in text
    rows = list(csv.DictReader((tmp_path / FOLDER.format(name="study") / "study.csv").open()))
    assert [int(r["seed"]) for r in rows] == [0, 1, 2]
    assert "3 femurs" in text and (tmp_path / "drilling_spread.png").is_file()
    worst = max(float(r["protrusion"]) for r in rows)
    assert f"{1e3 * worst:.3g} |" in text
