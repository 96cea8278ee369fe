"""Issue 22's front in the section beyond the paper (app/reports/force_study.py): the shipped studies'
summary, the preset it picks, the same figures as a fresh run, the section and the figure."""

from __future__ import annotations

import pytest
from matplotlib.figure import Figure

from vgtarm.app.reports import force_study
from vgtarm.app.reports.force_front import by_setting, choose
from vgtarm.app.reports.low_force import PresetRun, run_options
from vgtarm.errors import InputError
from vgtarm.experiment.cases import joint_reference, run_case
from vgtarm.experiment.presets import PRESETS


def _row(criterion, estimator, bandwidth, k_o, kp, kv, seed, error_mm, rms, peak, chatter):
    return {
        "criterion": criterion,
        "estimator": estimator,
        "estimator_bandwidth_hz": bandwidth,
        "observer_gain": k_o,
        "kp": kp,
        "kv": kv,
        "seed": str(seed),
        "max_tip_error_m": repr(error_mm * 1e-3),
        "rms_force_n": repr(rms),
        "peak_force_n": repr(peak),
        "chatter_n": repr(chatter),
        "success": "True",
        "real_time_factor": "50.0",  # a column the summary leaves out
    }


def test_the_summary_keeps_the_settings_and_figures_of_each_run(tmp_path):
    rows = [
        _row("effort", "kalman", "120.0", "400.0", "20000.0", "450.0", s, 0.0265 + s * 1e-3, 25.0, 79.0, 3.6)
        for s in (1, 0)
    ] + [_row("joint_limits", "difference", "", "1000.0", "15000.0", "600.0", 0, 0.0301234567, 28.0, 117.0, 8.1)]
    summary = force_study.summarise(rows)
    assert [r["seed"] for r in summary] == ["0", "1", "0"]  # sorted by setting, then seed
    assert summary[2]["max_tip_error_m"] == "3.01235e-05" and "real_time_factor" not in summary[0]
    path = tmp_path / "summary.csv"
    force_study.write_summary(summary, path)
    assert force_study.load_summary(path) == summary
    with pytest.raises(InputError, match="results.csv row without 'chatter_n'"):
        force_study.summarise([{k: v for k, v in rows[0].items() if k != "chatter_n"}])


def test_the_shipped_front_picks_the_low_force_preset():
    rows = force_study.load_summary()
    assert len(rows) == 560
    groups = by_setting(rows)
    pick = choose(groups)
    assert pick is not None
    chosen = groups[pick]
    low = PRESETS["low-force"]
    assert chosen.value("criterion") == low["criterion"] and chosen.value("estimator") == low["estimator"]
    for key, preset_key in (
        ("estimator_bandwidth_hz", "estimator_bandwidth_hz"),
        ("observer_gain", "observer_gain"),
        ("kp", "kp"),
        ("kv", "kv"),
    ):
        assert float(chosen.value(key)) == low[preset_key], key
    assert groups[pick].seeds == (0, 1, 2, 3, 4) and groups[pick].worst_mm <= force_study.ERROR_TARGET_MM


def test_the_shipped_preset_point_is_todays_run(robot):
    """The summary is not stale: the preset's seed-0 run, made now, has its figures to 6 digits."""
    spec = PresetRun(2)
    ik, options = run_options(robot, spec)
    result = run_case(robot, 2, reference=joint_reference(robot, 2, **ik), external_force=True, seed=0, **options)
    s = result.summary()
    low = PRESETS["low-force"]
    (row,) = [
        r
        for r in force_study.load_summary()
        if r["seed"] == "0"
        and r["criterion"] == "effort"
        and r["estimator"] == "kalman"
        and float(r["estimator_bandwidth_hz"]) == low["estimator_bandwidth_hz"]
        and float(r["observer_gain"]) == low["observer_gain"]
        and float(r["kp"]) == low["kp"]
        and float(r["kv"]) == low["kv"]
    ]
    for key in ("max_tip_error_m", "rms_force_n", "peak_force_n", "chatter_n"):
        assert row[key] == f"{s[key]:.6g}", key


def test_the_section_lists_the_fronts_and_the_preset():
    rows = force_study.load_summary()
    lines = force_study.section_lines(rows, "force_front.png")
    table = [line for line in lines if line.startswith("| ")]
    assert all(line.count(" | ") == table[0].count(" | ") for line in table)
    preset = [line for line in table if "(low-force preset)" in line]
    assert len(preset) == 1 and "| 0.0284 | 24.99 | 78.9 | 3.63 |" in preset[0]
    assert lines[-1] == "![tip error against actuator force](force_front.png)"
    figure = force_study.front_figure(rows)
    assert isinstance(figure, Figure) and len(figure.axes) == 2
