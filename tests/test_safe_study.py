"""The 60-run study of the safe variant in the section beyond the paper (app/reports/safe_study.py)."""

from __future__ import annotations

import math

import pytest

from vgtarm.app.reports import safe_study
from vgtarm.errors import InputError


def _rows():
    scm, cfc = [], []
    for mass in ("0.9", "1.1"):
        for seed in ("0", "1"):
            common = {"model_mass": mass, "seed": seed, "real_time_factor": "1.5", "ga_activations": "100"}
            scm.append({**common, "scm_variant": "safe", "success": "True", "max_tip_error_m": "0.0003"})
            held = mass == "0.9"
            scm.append({**common, "scm_variant": "paper", "success": str(held), "max_tip_error_m": "0.0009",
                        "simulated_time_s": "4.0" if held else "0.8"})  # fmt: skip
            cfc.append({**common, "max_tip_error_m": "0.00085"})
    return scm, cfc


def test_summary_table_and_figure(tmp_path):
    scm, cfc = _rows()
    rows = safe_study.summarise(scm, cfc)
    assert len(rows) == 4
    assert rows[0]["safe_max_mm"] == pytest.approx(0.3) and math.isnan(rows[0]["paper_diverged_s"])
    assert rows[-1]["paper_diverged_s"] == 0.8 and math.isnan(rows[-1]["paper_max_mm"])
    path = tmp_path / "s.csv"
    safe_study.write_summary(rows, path)
    back = safe_study.load_summary(path)
    assert back[0]["cfc_max_mm"] == pytest.approx(0.85)
    text = "\n".join(safe_study.section_lines(back, "f.png"))
    assert "| 1.1 | 0 of 2 | 0.300 / 0.300 mm | 2 of 2 | 2 of 2 (from 0.800 s) |" in text
    assert "paper diverged 2" in text and "below CFC's on 4 of 4 runs" in text
    assert len(safe_study.study_figure(back).axes) == 1


def test_missing_cfc_run_is_named():
    scm, cfc = _rows()
    with pytest.raises(InputError, match="model_mass = 1.1, seed = 1: no CFC run"):
        safe_study.summarise(scm, cfc[:-1])


def test_shipped_summary_has_the_60_runs():
    rows = safe_study.load_summary()
    assert len(rows) == 60, f"{len(rows)} rows in {safe_study.SUMMARY_FILE}: expected the study's 60"
    assert {r["model_mass"] for r in rows} == {0.9, 1.0, 1.1}
