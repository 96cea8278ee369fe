"""Drilling studies (issue 38): the study file's parsing and its one-line refusals, reproducible
points whose drawn feed is uniform and independent of the bone's perturbation, a real two-point
study whose rows are the direct runs' summaries (in this process and in worker processes alike),
the CSV table read back and its spreadsheet escaping, and ``vgtarm drill-study`` end to end. The
runs use a small bone (a 1 mm drill, layers of 1.2, 1.5 and 1.2 mm) to stay short."""

from __future__ import annotations

import argparse
import csv
import io
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from vgtarm.drilling import load_bone
from vgtarm.drilling.control import DrillingSettings
from vgtarm.drilling.loop import TARGETS, drilling_run, perturbed_bone
from vgtarm.drilling.study import (
    FEED_RANGE,
    DrillingStudy,
    DrillingStudyResult,
    check_drilling_study,
    load_drilling_study,
    meets_targets,
    parse_drilling_study,
    point_feed,
    run_drilling_study,
)
from vgtarm.errors import ConfigError, InputError
from vgtarm.markup import csv_cell

from .conftest import small_bone_of

ROOT = Path(__file__).resolve().parents[1]
BONES = ROOT / "examples" / "bones"
EXAMPLE = ROOT / "examples" / "studies" / "drilling_bones.toml"
SHORT = DrillingSettings(gap=0.2e-3, duration=8.0)


@pytest.fixture(scope="module")
def small_bone():
    return small_bone_of(1.2e-3, 1.5e-3, 1.2e-3)


@pytest.fixture(scope="module")
def tiny_study(small_bone):
    return DrillingStudy(bones=(small_bone,), seeds=(3, 8), settings=SHORT, name="tiny")


@pytest.fixture(scope="module")
def tiny_result(robot, tiny_study):
    return run_drilling_study(robot, tiny_study)


# -- the study file ---------------------------------------------------------------------------------


def test_the_example_study_is_100_seeded_femurs_with_feeds_in_range():
    study = load_drilling_study(EXAMPLE)
    points = study.points()
    assert len(points) == 100
    assert [p.seed for p in points] == list(range(100))
    assert study.bones[0] == load_bone(BONES / "femur_diaphysis.toml")
    assert study.spread == 0.3 and study.feed_range == FEED_RANGE and study.settings.duration == 60.0
    feeds = np.array([p.feed_limit for p in points])
    assert feeds.min() >= 0.5e-3 and feeds.max() <= 2.0e-3
    assert study.files == (EXAMPLE.parent / "../bones/femur_diaphysis.toml",)


def _file(**changes):
    head = {"bones": ["femur_diaphysis.toml"], "seeds": 2}
    head.update(changes)
    return {"drilling_study": {k: v for k, v in head.items() if v is not None}}


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"spread": 1.5}, "drilling_study.spread = 1.5: expected a number in [0, 1)"),
        ({"seeds": 0}, "drilling_study.seeds = 0: expected a count >= 1"),
        ({"seeds": [1, 1]}, "drilling_study.seeds = [1, 1]: expected distinct seeds"),
        ({"seeds": [1, -2]}, "drilling_study.seeds[1] = -2: expected a whole number from 0"),
        ({"seeds": {"start": 2}}, "drilling_study.seeds = {'start': 2}: expected a count"),
        ({"feed_range": [2e-3, 1e-3]}, "drilling_study.feed_range = [0.002, 0.001]: expected [min, max]"),
        ({"feed_range": [1e-3, 2e-3], "feed_limit": [1e-3]}, "drilling_study.feed_range = [0.001, 0.002]: expected no"),
        ({"feed_limit": [1e-3, 0.0]}, "drilling_study.feed_limit[1] = 0.0: expected a number in (0, 0.1] (m/s)"),
        ({"set_point": [20, -1]}, "drilling_study.set_point[1] = -1: expected a finite number > 0 (N)"),
        ({"mode": "force"}, "drilling_study.mode = 'force': expected one of ['explicit', 'admittance']"),
        ({"feedback": ["sensor", "sensor"]}, "drilling_study.feedback = ['sensor', 'sensor']: expected distinct"),
        ({"name": ""}, "drilling_study.name = '': expected a text of 1 to 200 characters"),
        ({"sedes": 3}, "drilling_study.sedes: unknown key; expected one of ['name', 'bones'"),
        ({"bones": []}, "drilling_study.bones = []: expected a bone file name"),
        ({"settings": {"gap": "x"}}, "drilling_study.settings.gap = 'x': expected a finite number"),
        ({"settings": {"substeps": 2.0}}, "drilling_study.settings.substeps = 2.0: expected a whole number"),
        ({"settings": {"tool_torque": 1}}, "drilling_study.settings.tool_torque = 1: expected True or False"),
        ({"settings": {"set_point": 5.0}}, "drilling_study.settings.set_point: a study axis; set drilling_study"),
        (
            {"settings": {"gain": 5.0}},
            "drilling_study.settings.gain: unknown setting; expected one of ['spindle_speed'",
        ),
    ],
)
def test_refusals_name_the_field_in_one_line(changes, message):
    with pytest.raises(ConfigError) as caught:
        parse_drilling_study(_file(**changes), source="s.toml", folder=BONES)
    assert str(caught.value).startswith(f"s.toml: {message}")
    assert "\n" not in str(caught.value)


def test_a_bad_bone_file_or_table_is_refused(tmp_path):
    with pytest.raises(ConfigError, match="missing.toml"):
        parse_drilling_study(_file(bones="missing.toml"), source="s.toml", folder=BONES)
    with pytest.raises(ConfigError, match=r"s.toml: unknown table \[study\]"):
        parse_drilling_study({**_file(), "study": {}}, source="s.toml", folder=BONES)
    (tmp_path / "s.toml").write_text("[drilling_study\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_drilling_study(tmp_path / "s.toml")


def test_the_dataclass_refuses_with_input_errors(small_bone):
    with pytest.raises(InputError, match=r"^spread = -0.1: expected a number in \[0, 1\)$"):
        DrillingStudy(bones=small_bone, spread=-0.1)
    with pytest.raises(InputError, match="^labels = "):
        DrillingStudy(bones=(small_bone,), labels=("a", "b"))


def test_settings_out_of_range_are_refused_against_the_robot_before_any_run(robot, small_bone):
    study = DrillingStudy(bones=small_bone, settings=DrillingSettings(gap=1.0))
    with pytest.raises(InputError, match=r"^drilling study, point 0 \(seed 0\): gap = 1.0: expected"):
        check_drilling_study(robot, study)
    with pytest.raises(InputError, match="gap = 1.0"):
        run_drilling_study(robot, study)


# -- the points -------------------------------------------------------------------------------------


def test_the_same_study_gives_the_same_points_in_grid_order(small_bone):
    spec = _file(seeds=[5, 9], mode=["explicit", "admittance"], set_point=[10.0, 20.0])
    first = parse_drilling_study(spec, folder=BONES).points()
    assert first == parse_drilling_study(spec, folder=BONES).points()
    assert [(p.seed, p.set_point, p.mode) for p in first] == [
        (s, f, m) for s in (5, 9) for f in (10.0, 20.0) for m in ("explicit", "admittance")
    ]
    for p in first:  # the feed is the seed's, shared by every set point and mode (paired runs)
        assert p.feed_limit == point_feed(p.seed)
    fixed = parse_drilling_study(_file(feed_limit=[1e-3, 2e-3]), folder=BONES).points()
    assert [(p.seed, p.feed_limit) for p in fixed] == [(0, 1e-3), (0, 2e-3), (1, 1e-3), (1, 2e-3)]


def test_the_drawn_feed_is_uniform_and_independent_of_the_bone(small_bone):
    """Kolmogorov-Smirnov against U(0.5, 2) mm/s over 400 seeds, and no correlation with the first
    layer's thickness factor, which the bone's own generator of the same seed draws first."""
    seeds = range(400)
    feeds = np.array([point_feed(s) for s in seeds])
    assert stats.kstest(feeds, stats.uniform(0.5e-3, 1.5e-3).cdf).pvalue > 0.01
    factors = np.array([perturbed_bone(small_bone, s).layers[0].thickness for s in seeds])
    assert abs(np.corrcoef(feeds, factors)[0, 1]) < 0.15  # 3 standard errors of 400 independent draws


# -- a real study -----------------------------------------------------------------------------------


def _same(a, b):
    return a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b))


def test_rows_are_the_direct_runs_summaries(robot, small_bone, tiny_study, tiny_result):
    assert [r["point"] for r in tiny_result.rows] == [0, 1]
    for point, row in zip(tiny_result.points, tiny_result.rows, strict=True):
        bone = perturbed_bone(small_bone, point.seed, 0.3)
        settings = DrillingSettings(gap=0.2e-3, duration=8.0, feed_limit=point_feed(point.seed))
        summary = drilling_run(robot, bone, settings, nominal=small_bone).summary()
        assert row["seed"] == point.seed and row["feed_limit"] == settings.feed_limit
        assert row["thickness"] == bone.thickness and row["density_1"] == bone.layers[1].density
        assert row["success"] == summary["success"] and row["reason"] == summary["reason"]
        for key in ("protrusion", "detection_delay", "detection_delay_after_drop", "thrust_error_rms_max"):
            assert _same(row[key], summary[key]), key
        assert row["lateral_deviation_max"] == summary["lateral_deviation_max"]
        assert row["false_detections"] == summary["false_detections"]
        for i, layer in enumerate(summary["layers"]):
            assert _same(row[f"thrust_error_rms_{i}"], layer["thrust_error_rms"])
        missed = sum(math.isnan(t["detected_time"]) for t in summary["transitions"])
        assert row["transitions_missed"] == missed
        delays = [t["detected_time"] - t["true_time"] for t in summary["transitions"]]
        assert _same(row["transition_delay_max"], float(np.nanmax(delays)) if not np.isnan(delays).all() else math.nan)
        within = all(meets_targets(row).values())
        assert row["within_targets"] == within
        assert within == (
            summary["success"]
            and summary["thrust_error_rms_max"] <= TARGETS["thrust_error_rms"]
            and summary["protrusion"] <= TARGETS["protrusion"]
            and summary["detection_delay"] <= TARGETS["detection_delay"]
            and summary["lateral_deviation_max"] <= TARGETS["lateral_deviation"]
            and summary["axis_error_max"] <= TARGETS["axis_error"]
            and summary["false_detections"] == 0
            and missed == 0
        )


def test_worker_processes_give_the_same_rows(robot, tiny_study, tiny_result):
    seen = []
    parallel = run_drilling_study(robot, tiny_study, workers=2, progress=lambda done, total: seen.append((done, total)))
    assert seen[-1] == (2, 2)
    assert len(parallel.rows) == len(tiny_result.rows)
    for a, b in zip(parallel.rows, tiny_result.rows, strict=True):
        assert a.keys() == b.keys()
        assert all(_same(a[k], b[k]) for k in a), [k for k in a if not _same(a[k], b[k])]


def test_table_spread_and_counts(tiny_result):
    read = list(csv.DictReader(io.StringIO(tiny_result.table())))
    assert list(read[0]) == tiny_result.columns()
    for line, row in zip(read, tiny_result.rows, strict=True):
        assert float(line["protrusion"]) == row["protrusion"]  # every double as it is
        assert line["mode"] == row["mode"] and int(line["seed"]) == row["seed"]
    spread = tiny_result.spread()
    assert "point" not in spread and "seed" not in spread and "success" not in spread
    values = [r["protrusion"] for r in tiny_result.rows]
    assert spread["protrusion"] == {
        "min": min(values),
        "median": float(np.median(values)),
        "max": max(values),
        "count": 2.0,
    }
    counts = tiny_result.within_targets()
    assert counts["runs"] == 2
    assert counts["within_targets"] == sum(r["within_targets"] for r in tiny_result.rows)
    assert counts["false_detections"] == sum(r["false_detections"] for r in tiny_result.rows)
    fig = tiny_result.figure()
    assert len(fig.axes) == 3


# -- CSV ------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("value", "cell"),
    [
        ("=HYPERLINK(1)", "'=HYPERLINK(1)"),
        ("+1", "'+1"),
        ("-1", "'-1"),
        ("@sum", "'@sum"),
        ("\tx", "'\tx"),
        ("femur.toml", "femur.toml"),
        (math.nan, ""),
        (None, ""),
        (0.1, "0.1"),
        (1 / 3, "0.3333333333333333"),
        (-2.0, "-2.0"),
        (True, True),
        (3, 3),
    ],
)
def test_csv_cells(value, cell):
    assert csv_cell(value) == cell


def test_the_table_keeps_a_hostile_label_one_cell(tiny_study):
    label = '=cmd|"a,b"\nnext'
    rows = [{"point": 0, "bone": label, "protrusion": math.nan, "within_targets": False}]
    text = DrillingStudyResult(tiny_study, (), rows, 0.0).table()
    read = list(csv.reader(io.StringIO(text)))
    assert read == [["point", "bone", "protrusion", "within_targets"], ["0", "'" + label, "", "False"]]


# -- the command ------------------------------------------------------------------------------------


def _toml(data, table=""):
    """A bone's mapping as TOML text (strings, numbers, tables, one array of tables)."""
    lines, later = [], []
    for key, value in data.items():
        if isinstance(value, dict):
            later.append(_toml(value, f"{table}{key}."))
        elif isinstance(value, list):
            later += [f"[[{table}{key}]]\n" + _toml(item) for item in value]
        else:
            lines.append(f"{key} = {value!r}" if not isinstance(value, str) else f'{key} = "{value}"')
    head = f"[{table[:-1]}]\n" if table and lines else ""
    return head + "\n".join(lines) + "\n" + "\n".join(later)


def test_the_command_writes_the_folder(tmp_path, small_bone, capsys):
    from vgtarm.app.cli import drill_study

    (tmp_path / "small.toml").write_text(_toml(small_bone.to_dict()))
    assert load_bone(tmp_path / "small.toml") == small_bone
    (tmp_path / "study.toml").write_text(
        '[drilling_study]\nbones = "small.toml"\nseeds = [3, 8]\n'
        "[drilling_study.settings]\ngap = 0.0002\nduration = 8.0\n"
    )
    parser = argparse.ArgumentParser()
    drill_study.add_parser(parser.add_subparsers())
    args = parser.parse_args(
        ["drill-study", str(tmp_path / "study.toml"), "--out", str(tmp_path / "out"), "--workers", "2"]
    )
    assert args.run(args) == 0
    out = capsys.readouterr().out
    assert "within every target:" in out and "protrusion" in out
    assert sorted(p.name for p in (tmp_path / "out").iterdir() if not p.name.startswith(".")) == [
        "spread.png",
        "study.csv",
        "summary.json",
    ]
    rows = list(csv.DictReader(io.StringIO((tmp_path / "out" / "study.csv").read_text())))
    assert [r["seed"] for r in rows] == ["3", "8"] and rows[0]["bone"] == "small.toml"
