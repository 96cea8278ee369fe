"""report.html tells the whole story (issue 27, item 5): the sections of report.md under the same
headings, every run linked to its folder and summary, one self-contained file, checked in Chromium;
and the Markdown converter that makes the page from report.md keeps users' text inert."""

from __future__ import annotations

import dataclasses
import html
import itertools
import re
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.text import Text

import vgtarm
from tests.test_html_report import browser_tab
from tests.test_injection import folder_name, fuzz, hostile
from tests.test_plotting import make_result
from tests.viz_support import short_case1_run
from vgtarm.app.pictures.drawing import STACK_FIGURE_SIZE, pose_figure
from vgtarm.app.pictures.plotting import comparison_figure, joint_groups, spans_decades
from vgtarm.app.reports import reproduce as reproduce_module
from vgtarm.app.reports.beyond import beyond_runs
from vgtarm.app.reports.html import ReportRun, figure_errors, page_figures, render_html
from vgtarm.app.reports.markdown_html import headings, to_html
from vgtarm.app.reports.runs import RunSpec, folder_cell
from vgtarm.errors import escape
from vgtarm.markup import md_cell, md_code, md_text
from vgtarm.model.parameters import JOINT_NAMES
from vgtarm.simulation import JointReference, SimulationResult

#: Samples of the shortened references of the page's reproduction (0.3 s: seconds, not minutes).
SHORT_SAMPLES = 301
SPECS = [RunSpec(1, "cfc", False, "exact"), RunSpec(1, "scm", False, "exact")]
#: The sections every reproduction's report holds (report.md and report.html).
SECTIONS = [
    "vgtarm: the paper's case studies reproduced",
    "Maximum tip error, ours beside the paper's",
    "Figures",
    "Reading",
    "Beyond the paper: tracking under the tool force",
    "Safe switching control on 60 runs (issue 23)",
    "The low-force preset (issue 22)",
    "The trade-off: tip error against actuator force (issue 22)",
    "Tool tasks: drilling and cutting",
    "Drilling bone under force control",
    "The spread over seeded bones",
    "What bounds the remaining error",
]


class Page(HTMLParser):
    """Headings (level, text), links, images' sources, scripts' sources and the number of tables."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.headings: list[tuple[int, str]] = []
        self.links: list[tuple[str, str]] = []
        self.images: list[str] = []
        self.script_sources: list[str] = []
        self.elements: list[str] = []
        self._heading: list[str] | None = None
        self._link: list[str] | None = None
        self._href = ""

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        values = dict(attrs)
        self.elements.append(tag)
        if re.fullmatch(r"h[1-6]", tag):
            self._heading = []
        elif tag == "a":
            self._link, self._href = [], values.get("href") or ""
        elif tag == "img":
            self.images.append(values.get("src") or "")
        elif tag == "script" and "src" in values:
            self.script_sources.append(values["src"] or "")

    def handle_endtag(self, tag: str) -> None:
        if re.fullmatch(r"h[1-6]", tag) and self._heading is not None:
            self.headings.append((int(tag[1]), "".join(self._heading)))
            self._heading = None
        elif tag == "a" and self._link is not None:
            self.links.append((self._href, "".join(self._link)))
            self._link = None

    def handle_data(self, data: str) -> None:
        for sink in (self._heading, self._link):
            if sink is not None:
                sink.append(data)


def parse(page: str) -> Page:
    parser = Page()
    parser.feed(page)
    parser.close()
    return parser


def markdown_headings(text: str) -> list[tuple[int, str]]:
    """The ATX headings of a Markdown text, as a renderer shows them (escapes and references resolved)."""
    found = []
    for line in text.splitlines():
        match = re.match(r"^(#{1,6})[ \t]+(.*?)[ \t]*$", line)
        if match:
            shown = html.unescape(re.sub(r"\\([!-/:-@\[-`{-~])", r"\1", match.group(2)))
            found.append((len(match.group(1)), re.sub(r"`([^`]*)`", r"\1", shown)))
    return found


@pytest.fixture(scope="module")
def reproduction(robot, tmp_path_factory) -> Path:
    """``reproduce`` of two case-1 runs with the section beyond the paper, on references cut to 0.3 s."""
    full_reference = reproduce_module.joint_reference

    def short(robot, case, rates="exact", duration=None):
        full = full_reference(robot, case, rates=rates, duration=duration)
        keep = slice(0, SHORT_SAMPLES)
        return JointReference(full.t[keep], full.q[keep], full.qd[keep], full.qdd[keep])

    out = tmp_path_factory.mktemp("reproduction") / "results"
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(reproduce_module, "joint_reference", short)
        reproduce_module.reproduce(robot, out, runs=SPECS, workers=1)
    return out


def test_report_html_has_report_mds_headings(reproduction):
    markdown = (reproduction / "report.md").read_text("utf-8")
    page = parse((reproduction / "report.html").read_text("utf-8"))
    assert page.headings == markdown_headings(markdown)
    assert [text for _, text in page.headings] == SECTIONS
    assert [(h.level, h.text) for h in headings(markdown)] == page.headings


def test_report_html_links_every_run_to_its_folder_and_summary(reproduction):
    page = parse((reproduction / "report.html").read_text("utf-8"))
    hrefs = [href for href, _ in page.links]
    folders = [s.folder for s in SPECS] + [b.folder for b in beyond_runs() if b.in_table]
    for folder in folders:
        assert f"{folder}/" in hrefs and f"{folder}/summary.json" in hrefs, folder
    for href in hrefs:  # relative, and each leads to what the run saved
        assert not re.match(r"^[a-z]+:|^/", href), href
        assert (reproduction / href).exists(), href
    markdown = (reproduction / "report.md").read_text("utf-8")
    assert "[case1\\_cfc/](case1_cfc/) [summary](case1_cfc/summary.json)" in markdown


def test_report_html_is_one_file_that_holds_its_figures_and_plotly_once(reproduction):
    text = (reproduction / "report.html").read_text("utf-8")
    page = parse(text)
    assert page.script_sources == [] and "iframe" not in page.elements and "link" not in page.elements
    assert text.count("window.PlotlyConfig") == 1 and text.count("* plotly.js v") == 1
    markdown = (reproduction / "report.md").read_text("utf-8")
    assert len(page.images) == markdown.count("![") >= 5
    assert all(src.startswith("data:image/png;base64,") for src in page.images)
    assert not (reproduction / "plotly.min.js").exists()


def test_reproduced_page_in_a_real_browser(reproduction):
    plots = 4  # tip error, efforts, paths, the mechanism along case 1
    with browser_tab(reproduction / "report.html", plots) as (tab, problems):
        shown = tab.evaluate(
            """() => Array.from(document.querySelectorAll('h1, h2, h3, h4')).map(h => ({
                text: h.textContent, visible: h.getBoundingClientRect().height > 0}))"""
        )
        images = tab.evaluate("() => Array.from(document.images).map(i => i.complete && i.naturalWidth > 0)")
    assert [h["text"] for h in shown] == SECTIONS and all(h["visible"] for h in shown)
    assert images and all(images)
    assert not problems, problems


# -- the converter ----------------------------------------------------------------------------


def test_converter_reads_the_reports_blocks():
    text = "\n".join(
        [
            "# Title `code`",
            "",
            "A *first* paragraph",
            "on two lines with **bold**.",
            "",
            "| a | b |",
            "| --- | --- |",
            "| 1 \\| 2 | [`x/`](<x/>) |",
            "",
            "- one",
            "  continued",
            "- two",
            "",
            "![a figure](fig.png)",
        ]
    )
    out = re.sub(r">\n<", "><", to_html(text, first_table_id="t"))  # the blocks' own line breaks aside
    assert '<h1 id="title-code">Title <code>code</code></h1>' in out
    assert "<p>A <em>first</em> paragraph\non two lines with <strong>bold</strong>.</p>" in out
    assert '<table id="t"><thead><tr><th>a</th><th>b</th></tr></thead>' in out
    assert '<td>1 | 2</td><td><a href="x/"><code>x/</code></a></td>' in out
    assert "<ul><li>one\ncontinued</li><li>two</li></ul>" in out
    assert '<img src="fig.png" alt="a figure">' in out


def test_converter_writes_no_link_with_a_scheme_and_no_image_outside_the_folder():
    out = to_html("[x](javascript:alert(1)) [y](http://example.invalid)\n\n![i](/etc/passwd)\n\n![j](http://x/y.png)")
    assert "<a" not in out and "<img" not in out


@fuzz(80)
@given(text=hostile)
def test_users_text_through_markup_shows_as_written_in_the_page(text: str) -> None:
    """A user's string through md_text, md_cell or md_code, converted: the characters as written, no
    element but the converter's own."""
    for markdown, wrapper in (
        (f"# {md_text(text)}", "h1"),
        (f"para {md_text(text)} end", "p"),
        (f"- {md_text(text)}", "li"),
        (f"| h |\n| --- |\n| {md_cell(text)} |", "td"),
        (f"x {md_code(text)} y", "p"),
        (f"| h |\n| --- |\n| {folder_cell(folder_name(text))} |", "td"),
    ):
        page = parse(to_html(markdown))
        expected = {"h1": {"h1"}, "p": {"p", "code"}, "li": {"ul", "li"}, "td": {"table", "thead", "tr", "th"}}
        allowed = expected[wrapper] | {"tbody", "td", "code", "a"}
        assert set(page.elements) <= allowed, (markdown, page.elements)
        body = html.unescape(re.sub(r"<[^>]+>", "", to_html(markdown)))
        shown = escape(folder_name(text) if "summary" in markdown else text).strip()
        assert shown in body, markdown
        for href, _ in page.links:
            assert re.fullmatch(r"[A-Za-z0-9%._~/-]+", href), href


# -- the run's figure: no overlapping labels, efforts per module, log errors across decades ----


def _stack_run(names: tuple[str, ...], controller: str = "scm", seed: int = 0) -> SimulationResult:
    """A synthetic run of a robot with joints ``names`` (the plotting tests' run, its joints replaced)."""
    base = make_result(controller, seed=seed)
    n, rng = len(names), np.random.default_rng(seed)
    angle = np.pi * base.t[:, None] + np.arange(n)
    effort = np.where([name.startswith("psi") for name in names], 0.5, 50.0) * np.sin(angle)
    q = 0.1 + 0.01 * np.sin(angle)
    return dataclasses.replace(
        base,
        q=q + 1e-4 * rng.standard_normal(q.shape),
        q_desired=q,
        qd=np.zeros_like(q),
        qd_desired=np.zeros_like(q),
        effort=effort,
        metadata={**base.metadata, "joint_names": list(names)},
    )


def drawn_text_boxes(fig: Figure) -> list[tuple[str, Any]]:
    """The texts Matplotlib draws on ``fig`` (titles, axis and tick labels, legends) with their
    window extents from the figure's renderer (a tick label outside the view is not drawn)."""
    canvas = FigureCanvasAgg(fig)
    drawn: list[Text] = []
    draw = Text.draw

    def recording(self: Text, renderer: Any) -> None:
        if self.get_visible() and self.get_text().strip():
            drawn.append(self)
        draw(self, renderer)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(Text, "draw", recording)
        canvas.draw()
    renderer = canvas.get_renderer()
    return [(t.get_text(), t.get_window_extent(renderer)) for t in drawn]


def overlapping(boxes: list[tuple[str, Any]]) -> list[tuple[str, str]]:
    return [(a, b) for (a, box_a), (b, box_b) in itertools.combinations(boxes, 2) if box_a.overlaps(box_b)]


SIX_MODULE_JOINTS = tuple(
    "s1 v1 p1 s2 v2 p2 psi3 s3 v3 p3 s4 v4 p4 psi5 s5 v5 p5 s6 v6 p6 psi7".split()
)  # examples/six_modules.toml


@pytest.mark.parametrize("joints", [JOINT_NAMES, SIX_MODULE_JOINTS], ids=["paper", "six_modules"])
@pytest.mark.parametrize("count", [1, 2])
def test_a_runs_figure_has_no_overlapping_labels_and_a_panel_per_module(joints, count):
    runs = [_stack_run(joints, "cfc", 1), _stack_run(joints, "scm", 2)][:count]
    fig = comparison_figure(runs)
    boxes = drawn_text_boxes(fig)
    assert len(boxes) > 40
    assert overlapping(boxes) == []
    groups = joint_groups(joints)
    modules = sum(name.startswith("s") for name in joints)
    assert len(groups) == modules + 1  # a panel per module's legs, one for the twists
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert labels.count("module 1 (N)") == count and sum("twist" in label for label in labels) == count


def test_the_checker_sees_an_overlap():
    fig = Figure(figsize=(3, 2))
    fig.text(0.5, 0.5, "one label")
    fig.text(0.52, 0.5, "another label")
    assert overlapping(drawn_text_boxes(fig)) == [("one label", "another label")]


def test_error_axes_are_logarithmic_where_errors_span_decades(robot):
    assert spans_decades([np.array([1e-3, 0.5])]) and not spans_decades([np.array([0.01, 0.5, np.nan, 0.0])])
    run = short_case1_run(robot, "cfc", 0.05)
    wide = dataclasses.replace(run, tip_error=np.geomspace(1e-8, 1e-3, len(run.t)))  # five decades
    narrow = dataclasses.replace(run, tip_error=np.linspace(0.2e-3, 1e-3, len(run.t)))
    for made, scale in ((wide, "log"), (narrow, "linear")):
        error_axes = next(ax for ax in comparison_figure([made]).axes if ax.get_title() == "Tip position error")
        assert error_axes.get_yscale() == scale
        page = render_html(robot, [ReportRun(RunSpec(1, "cfc", False, "exact"), "run", "run", made)], max_frames=2)
        figure = page.split('id="tip-error"')[1].split("</script>")[0]
        assert ('"type":"log"' in figure.replace(" ", "")) == (scale == "log")


def _drawn_heights(robot: Any, **options: Any) -> list[tuple[float, bool]]:
    """Height (in) of the robot as drawn in each plane view of its pose figure, and whether all of
    it lies inside its panel (nothing cut off)."""
    fig = pose_figure(robot, robot.parameters.home, **options)
    FigureCanvasAgg(fig).draw()
    found = []
    for ax in fig.axes[:2]:  # the plane views
        points = np.concatenate([ax.transData.transform(line.get_xydata()) for line in ax.lines])
        points = points[np.isfinite(points).all(axis=1)]
        box = ax.get_window_extent()
        inside = bool(np.all((points >= [box.x0 - 1, box.y0 - 1]) & (points <= [box.x1 + 1, box.y1 + 1])))
        found.append((float(np.ptp(points[:, 1])) / fig.dpi, inside))
    return found


def test_the_six_module_drawing_is_drawn_larger_and_whole():
    six = vgtarm.load_robot("examples/six_modules.toml")
    now = _drawn_heights(six)
    before = _drawn_heights(six, figsize=STACK_FIGURE_SIZE)  # the stack figure's size of before
    for (height, inside), (earlier, _) in zip(now, before, strict=True):
        assert inside and height > 1.25 * earlier, (height, earlier)


def test_efforts_panel_per_module_and_a_menu_that_shows_one_run(robot):
    runs = [
        ReportRun(RunSpec(1, "cfc", False, "exact"), "one", "one", short_case1_run(robot, "cfc", 0.05)),
        ReportRun(RunSpec(1, "scm", False, "exact"), "two", "two", short_case1_run(robot, "scm", 0.05)),
    ]
    figure = {div: fig for div, _, fig in page_figures(robot, runs, max_frames=2)}["efforts"]
    n = len(JOINT_NAMES)
    assert len(figure["data"]) == 2 * n and [t["visible"] for t in figure["data"]] == [True] * n + [False] * n
    titles = [figure["layout"][key]["title"]["text"] for key in ("yaxis", "yaxis2", "yaxis3")]
    assert titles == ["module 1 (N)", "module 2 (N)", "twist (N m)"] and "yaxis4" not in figure["layout"]
    (menu,) = figure["layout"]["updatemenus"]
    assert [b["label"] for b in menu["buttons"]] == ["one", "two"]
    for i, button in enumerate(menu["buttons"]):
        assert button["args"][0]["visible"] == [k // n == i for k in range(2 * n)]
    assert figure_errors(figure) == []
    single = {div: fig for div, _, fig in page_figures(robot, runs[:1], max_frames=2)}["efforts"]
    assert "updatemenus" not in single["layout"]
