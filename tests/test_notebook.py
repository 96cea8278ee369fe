"""A Robot, a run and a study show a useful, escaped HTML table in a notebook (`_repr_html_`),
checked by parsing the HTML."""

from __future__ import annotations

from dataclasses import replace
from html.parser import HTMLParser
from pathlib import Path

import pytest

from vgtarm.control import ComputedForceControl
from vgtarm.simulation import simulate
from vgtarm.study.runner import SHOWN_ROWS, StudyRun

from .test_simulation import smooth_reference

HOSTILE = "<script>alert(1)</script><img src=x onerror=alert(2)>"


class _Cells(HTMLParser):
    """The tags, the table's cells and captions, and the images' sources of a page."""

    def __init__(self) -> None:
        super().__init__()
        self.tags: list[str] = []
        self.rows: list[list[str]] = []
        self.caption = ""
        self.images: list[str] = []
        self._where = ""

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append(tag)
        if tag == "tr":
            self.rows.append([])
        if tag in ("td", "th", "caption"):
            self._where = tag
            if tag != "caption":
                self.rows[-1].append("")
        if tag == "img":
            self.images.append(dict(attrs).get("src") or "")

    def handle_endtag(self, tag: str) -> None:
        if tag in ("td", "th", "caption"):
            self._where = ""

    def handle_data(self, data: str) -> None:
        if self._where == "caption":
            self.caption += data
        elif self._where:
            self.rows[-1][-1] += data


def _parse(html: str) -> _Cells:
    cells = _Cells()
    cells.feed(html)
    return cells


def test_a_robot_shows_its_joints_with_limits_and_home(robot):
    page = _parse(robot._repr_html_())
    header, *joints = page.rows
    assert header == ["joint", "unit", "lower", "upper", "home"]
    assert [row[0] for row in joints] == list(robot.joint_names)
    p = robot.parameters
    for row, lo, hi, home in zip(joints, p.lower, p.upper, p.home, strict=True):
        assert [float(x) for x in row[2:]] == pytest.approx([lo, hi, home], rel=1e-5)
    assert f"{robot.n_joints} joints" in page.caption and robot.fingerprint in page.caption


def test_a_hostile_robot_name_stays_text(robot):
    named = robot.with_parameters(replace(robot.parameters, name=HOSTILE))
    page = _parse(named._repr_html_())
    assert "script" not in page.tags and "img" not in page.tags
    assert HOSTILE in page.caption


def test_a_run_shows_its_figures_and_a_plot(robot):
    cfc = ComputedForceControl.with_gains(15000.0, 600.0)
    result = simulate(robot, smooth_reference(robot, duration=0.05), cfc, metadata={"case": HOSTILE})
    page = _parse(result._repr_html_())
    table = {row[0]: row[1] for row in page.rows[1:]}
    assert float(table["max_tip_error_m"]) == pytest.approx(result.summary()["max_tip_error_m"], rel=1e-5)
    assert table["controller"] == "cfc" and table["success"] == "True" and table["case"] == HOSTILE
    assert page.tags.count("img") == 1 and page.images[0].startswith("data:image/png;base64,")
    assert "script" not in page.tags


def test_a_study_shows_its_varied_columns_and_at_most_fifty_rows():
    rows = [
        {"id": f"p{i:03d}", "kp": 1000.0 * (i % 3), "case": 1, "max_tip_error_m": 1e-4 * i, "success": True}
        for i in range(SHOWN_ROWS + 7)
    ]
    rows[0]["error"] = HOSTILE
    done = StudyRun(rows, len(rows), 0, len(rows), 0, (), 3.5, Path("out"))
    page = _parse(done._repr_html_())
    header, *shown = page.rows
    assert header[:2] == ["id", "kp"] and "case" not in header  # the same in every run: not a column
    assert len(shown) == SHOWN_ROWS and f"the first {SHOWN_ROWS} shown" in page.caption
    assert shown[0][header.index("error")] == HOSTILE and "script" not in page.tags
