"""The low-force preset's rows of ``vgtarm reproduce`` (issue 22): one definition of the preset, the
rows' runs equal to ``vgtarm simulate``'s, the section's cells from the runs' summaries."""

from __future__ import annotations

import json
from types import SimpleNamespace

import pytest

from vgtarm.app.cli import presets as cli_presets
from vgtarm.app.cli.command import main
from vgtarm.app.reports.low_force import (
    PresetRun,
    low_force_runs,
    low_force_section,
    run_low_force_one,
    simulate_command,
)
from vgtarm.app.reports.runs import paper_runs
from vgtarm.errors import InputError
from vgtarm.experiment.presets import PRESETS, preset_options

DURATION = "0.06"


def test_the_command_line_and_reproduce_read_the_same_preset():
    assert cli_presets.PRESETS is PRESETS
    ik, options = preset_options("low-force", tool_force=20.0)
    low = PRESETS["low-force"]
    assert ik == {"criterion": low["criterion"], "tool_force": 20.0}
    assert options["observer_gain"] == low["observer_gain"]
    assert options["estimator_bandwidth_hz"] == low["estimator_bandwidth_hz"]
    with pytest.raises(InputError, match="preset = 'fast': expected one of"):
        preset_options("fast", tool_force=0.0)


def test_the_rows_are_new_folders_beside_the_paper_runs():
    runs = low_force_runs()
    folders = [r.folder for r in runs]
    assert len(set(folders)) == len(folders) == 3
    assert {r.case for r in runs if r.preset} == {1, 2}
    assert not set(folders) & {s.folder for s in paper_runs()}
    assert all(f.startswith("beyond/case") for f in folders)  # the section's existing runs have no case prefix
    assert low_force_runs(SimpleNamespace(is_stack=False)) == runs  # type: ignore[arg-type]
    assert low_force_runs(SimpleNamespace(is_stack=True)) == []  # type: ignore[arg-type]  (a stack: not run)


@pytest.mark.parametrize("spec", [PresetRun(2), PresetRun(1, None)], ids=["case2-preset", "case1-observer"])
def test_a_row_is_the_run_of_its_simulate_command(robot, tmp_path, capsys, spec):
    """The row's run, on its first 60 ms, is `vgtarm simulate`'s with the same arguments, byte for byte."""
    made = run_low_force_one(robot, spec, tmp_path / "rows", seed=3, integrator="euler", substeps=1, duration=0.06)
    out = tmp_path / "cli"
    assert main([*simulate_command(spec, seed=3), "--duration", DURATION, "--out", str(out), "--quiet"]) == 0
    capsys.readouterr()
    ours = tmp_path / "rows" / spec.folder
    assert (ours / "timeseries.csv").read_bytes() == (out / "timeseries.csv").read_bytes()
    mine, theirs = (json.loads((f / "summary.json").read_text()) for f in (ours, out))
    for key in ("ik_criterion", "estimator", "observer_gain_per_s", "sensing", "seed", "rms_force_n", "chatter_n"):
        assert mine.get(key) == theirs.get(key), key
    if spec.preset:
        assert mine["ik_criterion"] == "effort" and made.summary()["rms_force_n"] > 0


def test_the_section_shows_each_rows_force_figures(robot, tmp_path):
    results = {
        spec: run_low_force_one(robot, spec, tmp_path, seed=0, integrator="euler", substeps=1, duration=0.03)
        for spec in (PresetRun(2), PresetRun(1, None), PresetRun(1))
    }
    baseline = run_low_force_one(
        robot, PresetRun(2, None), tmp_path, seed=0, integrator="euler", substeps=1, duration=0.03
    )
    lines = low_force_section(results, ("beyond/cfc_observer_realistic", baseline), seed=0)
    rows = [line for line in lines if line.startswith("| 1 |") or line.startswith("| 2 |")]
    assert [r.split(" | ")[1] for r in rows] == ["CFC + observer", "low-force preset"] * 2
    expected = [results[PresetRun(1, None)], results[PresetRun(1)], baseline, results[PresetRun(2)]]
    for line, run in zip(rows, expected, strict=True):
        s = run.summary()
        assert f"| {s['rms_force_n']:.2f} | {s['chatter_n']:.2f} | {s['actuator_energy_j']:.2f} |" in line
    assert "[beyond/cfc\\_observer\\_realistic/](beyond/cfc_observer_realistic/)" in rows[2]
    reading = [line for line in lines if line.startswith("- Case")]
    assert len(reading) == 2 and "RMS leg force" in reading[1]
