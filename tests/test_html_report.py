"""report.html: the table of report.md, decimated plots, one shared plotly.js, and the page checked in
a real headless Chromium (no JavaScript errors, every plot rendered, play moves the mechanism)."""

from __future__ import annotations

import dataclasses
import html
import os
import re
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.viz_support import short_case1_run
from vgtarm.app.cli import command as cli
from vgtarm.app.pictures.geometry import mechanism_geometry
from vgtarm.app.reports.html import (
    PLOTLY_JS,
    decimate_min_max,
    figure_errors,
    load_runs,
    mechanism_traces,
    page_figures,
    runs_from_reproduction,
    write_html_report,
)
from vgtarm.app.reports.reproduce import TABLE_COLUMNS, RunSpec, render_report
from vgtarm.errors import InputError
from vgtarm.markup import md_text

#: The browser: Debian's chromium (``VGTARM_CHROMIUM`` points elsewhere).
CHROMIUM = os.environ.get("VGTARM_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
#: Plots of a page of runs of one case: tip error, efforts, 3-D paths, the mechanism.
PLOTS_ONE_CASE = 4


@pytest.fixture(scope="module")
def runs(robot):
    return {
        RunSpec(1, "cfc", False, "exact"): short_case1_run(robot, "cfc"),
        RunSpec(1, "scm", False, "exact"): short_case1_run(robot, "scm"),
    }


@pytest.fixture(scope="module")
def page(robot, runs, tmp_path_factory) -> Path:
    return write_html_report(robot, runs_from_reproduction(runs), tmp_path_factory.mktemp("page"), max_frames=12)


def _cells(row_html: str) -> list[str]:
    return [html.unescape(c) for c in re.findall(r"<t[dh]>(.*?)</t[dh]>", row_html)]


def test_page_table_is_the_markdown_reports_table(runs, page):
    markdown = render_report(runs, {}, seed=0, integrator="euler", substeps=1, wall_time_s=1.0)
    md_rows = [line for line in markdown.splitlines() if line.startswith("| 1 |")]
    md_cells = [[c.strip() for c in row.strip("|").split("|")] for row in md_rows]
    table = re.search(r'<table id="summary-table">(.*?)</table>', page.read_text(), re.S).group(1)
    rows = re.findall(r"<tr>(.*?)</tr>", table, re.S)
    assert _cells(rows[0]) == list(TABLE_COLUMNS)
    html_cells = [_cells(r) for r in rows[1:]]
    assert [cells[:-1] for cells in html_cells] == [cells[:-1] for cells in md_cells]
    for spec, cells, md in zip(runs, html_cells, md_cells, strict=True):  # the folder cell: two links
        assert md[-1] == f"[{md_text(spec.folder)}/]({spec.folder}/) [summary]({spec.folder}/summary.json)"
        assert re.sub(r"<[^>]+>", "", cells[-1]) == f"{spec.folder}/ summary"
        assert re.findall(r'href="([^"]*)"', cells[-1]) == [f"{spec.folder}/", f"{spec.folder}/summary.json"]
    assert len(md_cells) == len(runs)


def test_page_is_one_file_with_plotly_inlined_once_and_needs_no_network(page):
    text = page.read_text()
    assert re.findall(r"<script[^>]*\bsrc=", text) == []
    assert "<link" not in text and "<iframe" not in text
    assert text.count("window.PlotlyConfig") == 1 and text.count("* plotly.js v") == 1
    assert sorted(p.name for p in page.parent.iterdir()) == ["report.html"]


def test_pages_of_one_folder_are_each_whole(robot, runs, tmp_path):
    specs = runs_from_reproduction(runs)
    first = write_html_report(robot, specs[:1], tmp_path, name="a.html", max_frames=4)
    second = write_html_report(robot, specs[1:], tmp_path, name="b.html", max_frames=4)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.html", "b.html"]
    for made in (first, second):
        assert made.read_text().count("* plotly.js v") == 1
        assert made.stat().st_size < 8_000_000


def test_min_max_decimation_keeps_peaks_ends_and_order():
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 6.0, 20_001)
    y = np.sin(t) + 0.01 * rng.standard_normal(t.size)
    y[12_345] = 9.0  # a spike
    y[777] = -9.0
    y[5_000:5_010] = np.nan
    index = decimate_min_max(t, y, 500)
    assert len(index) <= 500 and index[0] == 0 and index[-1] == len(t) - 1
    assert np.all(np.diff(index) > 0)
    assert 12_345 in index and 777 in index
    # every bucket's extremes are kept, so the decimated curve spans the same range everywhere
    assert np.nanmax(y[index]) == np.nanmax(y) and np.nanmin(y[index]) == np.nanmin(y)
    np.testing.assert_array_equal(decimate_min_max(t[:100], y[:100], 500), np.arange(100))
    with pytest.raises(InputError, match="max_points = 2"):
        decimate_min_max(t, y, 2)


def _decimate_min_max_loop(y: np.ndarray, max_points: int) -> np.ndarray:
    """The first implementation of :func:`decimate_min_max`, one bucket at a time: the reference."""
    n = len(y)
    if n <= max_points:
        return np.arange(n)
    buckets = (max_points - 2) // 2
    edges = np.linspace(1, n - 1, buckets + 1).astype(np.int64)
    keep = [0, n - 1]
    finite = np.where(np.isfinite(y), y, np.nan)
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        chunk = finite[lo:hi]
        if hi <= lo or np.isnan(chunk).all():
            continue
        keep += [lo + int(np.nanargmin(chunk)), lo + int(np.nanargmax(chunk))]
    return np.unique(np.array(keep, dtype=np.int64))


@pytest.mark.parametrize("n", [0, 1, 4, 5, 9, 10, 11, 37, 500, 501, 1203, 20_011])
@pytest.mark.parametrize("max_points", [4, 5, 10, 101, 1200])
def test_min_max_decimation_equals_the_loop_over_buckets(n, max_points):
    """The vectorised buckets give the loop's indices on data with NaN, inf, ties and -0.0."""
    rng = np.random.default_rng(n * 7919 + max_points)
    for trial in range(4):
        y = rng.standard_normal(n)
        if trial >= 1:  # ties, signed zeros and runs of non-finite samples (whole buckets of them)
            y = np.round(y, 1) * (1 - 2 * (rng.random(n) < 0.5))
            y[rng.random(n) < 0.1] = np.nan
            y[rng.random(n) < 0.05] = np.inf
            y[rng.random(n) < 0.05] = -np.inf
            if n > 20:
                start = int(rng.integers(0, n - 20))
                y[start : start + 20] = [np.nan, np.inf, -np.inf, -0.0][trial]
        if trial == 3 and n:
            y[:] = np.nan
        expected = _decimate_min_max_loop(y, max_points)
        index = decimate_min_max(np.arange(n, dtype=float), y, max_points)
        np.testing.assert_array_equal(index, expected, err_msg=f"trial {trial}")
        assert index.dtype == np.int64 or n <= max_points


def test_page_figures_are_what_plotlys_validation_makes_of_them(robot, runs):
    """The page writes its figures as plain dicts (no per-property validation): Plotly's validation
    would change nothing in them, template, typed arrays and animation frames included."""
    figures = page_figures(robot, runs_from_reproduction(runs), max_points=300, max_frames=5)
    assert [div for div, _, _ in figures] == ["tip-error", "efforts", "paths", "mechanism-1"]
    for div, _, figure in figures:
        assert figure_errors(figure) == [], div
    assert len(figures[-1][2]["frames"]) == 5
    # and the check sees a difference: a NumPy array Plotly would write as a typed array, no template
    wrong = figure_errors({"data": [{"type": "scatter", "x": np.arange(3.0)}], "layout": {}})
    assert any(w.startswith("figure.data[0].x:") for w in wrong) and any("template" in w for w in wrong)


def test_page_mechanism_traces_are_the_drawn_geometry(robot):
    q = robot.parameters.home
    geometry = mechanism_geometry(robot, q)
    legs = mechanism_traces(geometry)[0]
    xyz = np.array([legs["x"], legs["y"], legs["z"]], dtype=float).T.reshape(-1, 3, 3)[:, :2] / 1e3
    lengths = np.linalg.norm(xyz[:, 1] - xyz[:, 0], axis=1)
    names = legs["customdata"][::3]
    from vgtarm.model.parameters import JOINT_NAMES

    np.testing.assert_allclose(lengths, [q[JOINT_NAMES.index(n)] for n in names], rtol=0, atol=1e-12)
    tip = mechanism_traces(geometry)[-1]
    np.testing.assert_allclose(
        np.array([tip["x"], tip["y"], tip["z"]]).ravel() / 1e3, robot.tip_position(q), atol=1e-12
    )


def test_report_command_writes_a_page_for_saved_runs(runs, tmp_path, capsys):
    folders = []
    for spec, result in runs.items():
        folders.append(result.save(tmp_path / spec.folder))
    assert cli.main(["report", *map(str, folders), "--out", str(tmp_path / "page")]) == 0
    made = tmp_path / "page" / "report.html"
    assert made.is_file() and not (tmp_path / "page" / PLOTLY_JS).exists()
    assert [r.folder for r in load_runs(folders)] == [f.name for f in folders]
    links = re.findall(r'<a href="([^"]*)">', made.read_text())  # each run's folder and summary, relative
    assert links == [x for f in folders for x in (f"../{f.name}/", f"../{f.name}/summary.json")]
    assert all((made.parent / link).exists() for link in links)
    assert "report written to" in capsys.readouterr().out
    assert cli.main(["report", str(tmp_path / "nothing"), "--out", str(tmp_path / "x")]) == 1
    assert "nothing: not found" in capsys.readouterr().err


def _browser_or_skip():
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.skip("playwright is not installed: pip install -e '.[test]' to run the browser test")
    if not (Path(CHROMIUM).is_file() or shutil.which(CHROMIUM)):
        pytest.skip(f"no headless Chromium at {CHROMIUM}: apt-get install chromium (or set VGTARM_CHROMIUM) to run it")
    return sync_playwright


@contextmanager
def browser_tab(page: Path, plots: int) -> Iterator[tuple[Any, list[str]]]:
    """``page`` open in headless Chromium with its ``plots`` Plotly plots rendered: yields the tab and
    the list of problems seen (console errors, page errors, failed or network requests, dialogs
    such as an ``alert``, which are dismissed)."""
    sync_playwright = _browser_or_skip()
    problems: list[str] = []
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            tab = browser.new_page(viewport={"width": 1280, "height": 900})
            tab.on("console", lambda m: problems.append(f"console {m.type}: {m.text}") if m.type == "error" else None)
            tab.on("pageerror", lambda e: problems.append(f"page error: {e}"))

            def dialog(d: Any) -> None:
                problems.append(f"dialog {d.type}: {d.message}")
                d.dismiss()

            tab.on("dialog", dialog)
            tab.on("requestfailed", lambda r: problems.append(f"request failed: {r.url}"))
            tab.on("request", lambda r: None if r.url.startswith("file://") else problems.append(f"network: {r.url}"))
            tab.goto(page.as_uri(), wait_until="load")
            tab.wait_for_function(f"document.querySelectorAll('.js-plotly-plot').length === {plots}", timeout=60_000)
            yield tab, problems
        finally:
            browser.close()


def test_page_in_a_real_browser(page, tmp_path):
    with browser_tab(page, PLOTS_ONE_CASE) as (tab, problems):
        # the table: a header and one row per run
        assert tab.locator("#summary-table tbody tr").count() == 2
        assert tab.locator("#summary-table th").count() == len(TABLE_COLUMNS)
        # every plot rendered: its SVG layers, traces drawn, and a WebGL canvas for the 3-D ones
        report = tab.evaluate(
            """() => Array.from(document.querySelectorAll('.plotly-graph-div')).map(d => ({
                id: d.id, rendered: d.classList.contains('js-plotly-plot'),
                svg: d.querySelectorAll('svg.main-svg').length, traces: (d.data || []).length,
                lines: d.querySelectorAll('path.js-line').length, canvas: d.querySelectorAll('canvas').length,
                threeD: !!(d._fullLayout && d._fullLayout.scene)}))"""
        )
        assert [p["id"] for p in report] == ["tip-error", "efforts", "paths", "mechanism-1"]
        for plot in report:
            assert plot["rendered"] and plot["svg"] >= 1 and plot["traces"] >= 1, plot
            assert plot["canvas"] >= 1 if plot["threeD"] else plot["lines"] >= plot["traces"], plot
        # pressing play moves the mechanism: the legs' trace data and the slider change
        legs = "document.getElementById('mechanism-1').data.findIndex(t => t.customdata)"
        read = f"""() => {{ const d = document.getElementById('mechanism-1');
            return JSON.stringify([Array.from(d.data[{legs}].z), d._fullLayout.sliders[0].active]); }}"""
        before = tab.evaluate(read)
        tab.locator("#mechanism-1").scroll_into_view_if_needed()
        tab.locator("#mechanism-1 .updatemenu-button").first.click()
        tab.wait_for_function(
            """() => { const d = document.getElementById('mechanism-1');
                return d._fullLayout.sliders[0].active >= 3; }""",
            timeout=30_000,
        )
        after = tab.evaluate(read)
        assert after != before
        tab.screenshot(path=str(tmp_path / "report.png"), full_page=True)
    assert (tmp_path / "report.png").stat().st_size > 10_000
    assert not problems, problems


def test_twelve_runs_of_a_figure_each_look_different(robot, runs):
    """``vgtarm reproduce`` draws twelve runs, more than Plotly's ten colours: once the colours are used
    up the next dash pattern is taken, so no two runs' lines look alike (tip error and 3-D paths);
    the page still passes Plotly's validation."""
    from vgtarm.app.reports.html import COLOURS, run_line

    one = next(iter(runs_from_reproduction(runs)))
    many = [dataclasses.replace(one, label=f"run {k}") for k in range(12)]
    figures = {div: figure for div, _, figure in page_figures(robot, many, max_points=50, max_frames=2)}
    for div in ("tip-error", "paths"):
        lines = [(t["line"]["color"], t["line"]["dash"]) for t in figures[div]["data"] if t["name"].startswith("run ")]
        assert len(lines) == 12 and len(set(lines)) == 12, div
        assert figure_errors(figures[div]) == [], div
    assert len({(run_line(i, 1)["color"], run_line(i, 1)["dash"]) for i in range(4 * len(COLOURS))}) == 4 * len(COLOURS)
