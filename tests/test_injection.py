"""What users name shows as written in every page, document and figure vgtarm writes, and never
becomes markup (issue 20, item 4).

Users name the run folders, the robot (its file's ``name``), the title of a page, and write the
metadata of a saved run (its controller) and the rows of a study's table (controllers, error
messages that quote their files). The properties: a report.html made from a real short run in a
folder with a hostile name, of a robot with a hostile name, has exactly the elements and
attributes of the page of a plain name (html.parser), its scripts cannot be closed from inside,
and its Plotly labels hold no tag and no template field; report.md and a study's report.md keep
every table's columns and hold no raw ``<``; a Matplotlib title with ``$`` draws as written. The
hostile strings are drawn by hypothesis, derandomized (the project's rule: the same examples on
every run, as in ``tests/test_fuzz.py``).
"""

from __future__ import annotations

import dataclasses
import html
import json
import re
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.viz_support import short_case1_run
from vgtarm.app.cli import command as cli
from vgtarm.app.reports.html import load_runs, page_figures, render_html
from vgtarm.app.reports.reproduce import TABLE_COLUMNS, RunSpec, render_report
from vgtarm.errors import InputError, escape
from vgtarm.markup import html_text, md_cell, md_code, md_text, mpl_text, plotly_text
from vgtarm.model.parameters import NAME_LENGTH
from vgtarm.model.robot import Robot

#: The attacks of the issue and their relatives: each must show as written, nowhere act.
HOSTILE = (
    "<script>alert(1)</script>",
    "<img src=x onerror=alert(1)>",
    "](javascript:alert(1))",
    "[link](javascript:alert(1))",
    "![image](http://example.invalid/x.png)",
    "a | b | c",
    "two\nlines\r\n| x | y |",
    "</script><script>alert(1)</script>",
    "<!-- <script>",
    "{{ template }} %{y} %{fullData.name}",
    "`code` ``more``",
    "# heading",
    "*bold* _italic_ ~~struck~~ $x^2$",
    "&lt;b&gt; &amp; &#60;",
    '"\' onmouseover="alert(1)',
    '<b>bold</b> <a href="http://example.invalid">link</a>',
    "http://example.invalid www.example.invalid",
    "\x1b[31mred\\",
)
#: Characters that some format treats specially, and a few plain ones.
SPECIAL = "<>&\"'|`[]()*_~#!{}%$\\/:;=+-.@ \n\r\tab1"
#: Short runs: 0.05 s of case 1 (51 samples), a few points per curve and two animation frames.
DURATION_S = 0.05
MAX_POINTS = 40
MAX_FRAMES = 2


def fuzz(examples: int) -> Any:
    """Settings of every property here: reproducible, no per-example deadline."""
    return settings(
        max_examples=examples,
        deadline=None,
        derandomize=True,
        database=None,
        suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    )


#: A hostile string: pieces of the attacks and of special characters, joined.
hostile = st.lists(
    st.sampled_from(HOSTILE) | st.text(alphabet=SPECIAL, min_size=1, max_size=12), min_size=1, max_size=4
).map("".join)


def folder_name(text: str) -> str:
    """``text`` as the name of a folder (no ``/`` or NUL, not ``.`` or ``..``, at most 120 characters)."""
    name = text.replace("/", "\\").replace("\x00", "")[:120]
    return name if name.strip(".") else f"{name}run"


# -- the pages' parts, read back -----------------------------------------------------------


class Elements(HTMLParser):
    """The elements of a page in order, as (tag, attributes), the text inside each tag, and the
    text of each script."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.elements: list[tuple[str, tuple[tuple[str, str | None], ...]]] = []
        self.text: dict[str, list[str]] = {}
        self.scripts: list[str] = []
        self._open: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.elements.append((tag, tuple(attrs)))
        self._open.append(tag)

    def handle_endtag(self, tag: str) -> None:
        while self._open and self._open.pop() != tag:
            pass

    def handle_data(self, data: str) -> None:
        if self._open and self._open[-1] == "script":
            self.scripts.append(data)
        elif self._open:
            self.text.setdefault(self._open[-1], []).append(data)


def elements_of(page: str) -> Elements:
    parser = Elements()
    parser.feed(page)
    parser.close()
    return parser


def unescape_markdown(text: str) -> str:
    """What a Markdown renderer shows of inline text without markup: backslash escapes and
    character references resolved."""
    return html.unescape(re.sub(r"\\([!-/:-@\[-`{-~])", r"\1", text))


def unescaped(text: str, characters: str) -> list[str]:
    """The characters of ``characters`` in the Markdown ``text`` that no backslash escapes."""
    found, i = [], 0
    while i < len(text):
        if text[i] == "\\" and i + 1 < len(text):
            i += 2
            continue
        if text[i] in characters:
            found.append(text[i])
        i += 1
    return found


def table_columns(line: str) -> int:
    """Columns of a Markdown table row: its unescaped ``|`` less one."""
    return len(unescaped(line, "|")) - 1


def plotly_strings(figure: dict[str, Any]) -> list[str]:
    """Every string Plotly renders as text in a figure of the page: trace names, hover templates,
    titles (of the figure, its axes, its frames)."""
    found: list[str] = []

    def walk(node: Any, key: str = "") -> None:
        if isinstance(node, dict):
            for k, v in node.items():
                walk(v, k)
        elif isinstance(node, list):
            for v in node:
                walk(v, key)
        elif isinstance(node, str) and key in ("name", "hovertemplate", "text", "legendgroup"):
            found.append(node)

    walk(figure["data"])
    walk(figure["layout"].get("title"))
    walk({k: v for k, v in figure["layout"].items() if k.startswith(("xaxis", "yaxis"))})
    walk([frame.get("layout") for frame in figure.get("frames", [])])
    return found


# -- the helpers on their own ----------------------------------------------------------------


@fuzz(300)
@given(text=hostile)
def test_html_text_is_one_text_and_one_attribute_value(text: str) -> None:
    page = f'<p title="{html_text(text)}">{html_text(text)}</p>'
    parsed = elements_of(page)
    assert parsed.elements == [("p", (("title", escape(text)),))]
    assert "".join(parsed.text.get("p", [])) == escape(text)


@fuzz(300)
@given(text=hostile)
def test_plotly_text_holds_no_tag_and_no_template_field(text: str) -> None:
    shown = plotly_text(text)
    assert not set("<>{}") & set(shown)
    assert html.unescape(shown) == escape(text)  # Plotly shows the character references as characters
    assert plotly_text("case 1 CFC (case1_cfc)") == "case 1 CFC (case1_cfc)"


@fuzz(300)
@given(text=hostile)
def test_markdown_text_and_cells_are_inert(text: str) -> None:
    for shown in (md_text(text), md_cell(text), md_code(text)):
        assert "\n" not in shown and "\r" not in shown
        assert not unescaped(shown, "<>[]*_~$#|") or shown.startswith("`")
        assert table_columns(f"| {shown} | x |") == 2
    shown = md_text(text)
    assert unescape_markdown(shown) == escape(text)
    assert "<" not in shown and not unescaped(shown, "`")
    assert "://" not in shown.replace("\\://", "") and not re.search(r"(?i)www\.", shown)  # no bare autolink
    code = md_code(text)
    if code.startswith("`"):  # a code span only of text that a code span shows as it is
        assert code == f"`{escape(text)}`" and not set("`|<>&") & set(code[1:-1])


@fuzz(300)
@given(text=hostile)
def test_githubs_markdown_makes_text_of_the_escaped_names(text: str) -> None:
    """GitHub's own renderer (cmark-gfm; skipped without the ``cmarkgfm`` package) makes a
    paragraph and a table row of the escaped text, and no other element: the paragraph shows the
    text as written. (GitHub links an e-mail address after every escape: a ``mailto:`` link of the
    address as written is the one element allowed.)"""
    cmarkgfm = pytest.importorskip("cmarkgfm")
    document = (
        f"para {md_text(text)} end\n\n| a | b | c |\n| --- | --- | --- |\n| {md_cell(text)} | {md_code(text)} | x |\n"
    )
    out = cmarkgfm.github_flavored_markdown_to_html(document, options=cmarkgfm.cmark.Options.CMARK_OPT_UNSAFE)
    tags = set(re.findall(r"</?([a-z0-9]+)", out)) - {"p", "table", "thead", "tbody", "tr", "th", "td", "code"}
    assert tags <= {"a"} and out.count('<a href="') == out.count('<a href="mailto:'), out
    assert out.count("<td>") == 3, out
    paragraph = re.search(r"<p>para (.*) end</p>", out, re.S)
    assert paragraph is not None
    if "<a" not in paragraph.group(1):
        assert html.unescape(paragraph.group(1)) == escape(text)


def test_markup_leaves_plain_names_as_they_are() -> None:
    for name in ("case1_cfc", "reference (Bayram 2017, dimensions assumed)", "CFC + tool force (FD rates)"):
        assert html_text(name) == plotly_text(name) == mpl_text(name) == name
    assert md_text("reference (Bayram 2017, dimensions assumed)") == "reference (Bayram 2017, dimensions assumed)"
    assert md_code("case1_cfc/") == "`case1_cfc/`"
    assert md_text("case1_cfc") == "case1\\_cfc"  # shown as case1_cfc


@fuzz(60)
@given(text=hostile)
def test_matplotlib_text_starts_no_math(text: str) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.cbook import is_math_text
    from matplotlib.figure import Figure

    shown = mpl_text(text)
    assert not is_math_text(shown)
    assert shown.replace("\\$", "$") == escape(text)  # what Matplotlib shows of text that is not math
    fig = Figure(figsize=(2, 1), dpi=20)
    fig.suptitle(shown)
    FigureCanvasAgg(fig).draw()  # math that does not parse would raise here


# -- the pages and documents of real runs ------------------------------------------------


@pytest.fixture(scope="module")
def plain(robot: Robot, tmp_path_factory: pytest.TempPathFactory) -> Elements:
    """The page of a short run of a plain robot in a plain folder: the elements every page has."""
    folder = short_case1_run(robot, "cfc", DURATION_S).save(tmp_path_factory.mktemp("plain") / "run")
    runs = load_runs([folder])
    page = render_html(robot, runs, title="runs", intro="Runs: run", max_points=MAX_POINTS, max_frames=MAX_FRAMES)
    return elements_of(page)


def named(robot: Robot, name: str) -> Robot:
    """``robot`` under another name (the same model: no build)."""
    return Robot(dataclasses.replace(robot.parameters, name=name), backend=robot.backend)


def saved_run(robot: Robot, folder: Path, controller: str | None = None) -> Path:
    """A short run of ``robot`` saved in ``folder``; ``controller``: written into its summary.json
    (a saved run's metadata is a user's file too)."""
    short_case1_run(robot, "cfc", DURATION_S).save(folder)
    if controller is not None:
        summary = folder / "summary.json"
        data = json.loads(summary.read_text("utf-8"))
        data["controller"] = controller
        summary.write_text(json.dumps(data), "utf-8")
    return folder


def _shape(parsed: Elements) -> list[tuple[str, tuple[tuple[str, str | None], ...]]]:
    """The elements and attributes of a page, the values that come from users' names (the runs'
    links, percent-encoded, and the headings' ids, letters, digits and ``-``) left out."""
    named = {("a", "href")} | {(f"h{level}", "id") for level in range(1, 7)}
    return [(tag, tuple((a, None if (tag, a) in named else v) for a, v in attrs)) for tag, attrs in parsed.elements]


def assert_page_is_inert(page: str, plain: Elements, user: list[str]) -> None:
    """``page`` has the elements and attributes of the plain page, no script that can be closed
    or escaped from inside, and shows each of the ``user`` strings as written."""
    parsed = elements_of(page)
    assert _shape(parsed) == _shape(plain)
    assert not [t for t, attrs in parsed.elements if t in ("img", "iframe", "svg", "object", "embed")]
    links = [value for t, attrs in parsed.elements if t == "a" for a, value in attrs if a == "href"]
    assert links and all(re.fullmatch(r"(?!/)[A-Za-z0-9%._~/-]+", link or "") for link in links), links
    assert not [a for _, attrs in parsed.elements for a, _ in attrs if a.lower().startswith("on")]
    for script in parsed.scripts:
        assert not re.search(r"(?i)</script|<!--|<script", script)
    shown = " ".join(t for texts in parsed.text.values() for t in texts)
    for text in user:
        assert escape(text) in shown


@fuzz(25)
@given(name=hostile, folder=hostile, controller=hostile)
def test_a_page_of_hostile_names_has_the_plain_pages_elements(
    robot: Robot, plain: Elements, tmp_path_factory: pytest.TempPathFactory, name: str, folder: str, controller: str
) -> None:
    """Robot name, folder name, a saved run's controller and the title, all hostile: the page has
    the plain page's elements and attributes and shows each string as written; every label of
    its plots is free of tags and template fields and reads as written."""
    name = name[:NAME_LENGTH]
    hostile_robot = named(robot, name)
    where = saved_run(hostile_robot, tmp_path_factory.mktemp("runs") / folder_name(folder), controller)
    runs = load_runs([where])
    intro = f"Runs: {where.name}"
    page = render_html(hostile_robot, runs, title=name, intro=intro, max_points=MAX_POINTS, max_frames=MAX_FRAMES)
    assert_page_is_inert(page, plain, [name, where.name, controller.upper(), intro])
    label = runs[0].label
    assert where.name in label and controller.upper() in label
    for _, _, figure in page_figures(hostile_robot, runs, max_points=MAX_POINTS, max_frames=MAX_FRAMES):
        strings = plotly_strings(figure)
        for text in strings:
            assert not set("<>{}") & set(re.sub(r"%\{y:\.4g\}|</?extra>|<br>", "", text)), text
        assert any(escape(label) in html.unescape(text) for text in strings)


def report_md(result: Any) -> str:
    return render_report(
        {RunSpec(1, "cfc", False, "exact"): result}, {}, seed=0, integrator="euler", substeps=1, wall_time_s=1.0
    )


@fuzz(25)
@given(name=hostile)
def test_report_md_of_a_hostile_robot_keeps_its_lines_and_table(robot: Robot, name: str) -> None:
    """report.md of a run of a robot with a hostile name: no raw ``<``, the table's columns, and
    the lines of the report of a plain name but for the name itself, shown as written."""
    name = name[:NAME_LENGTH]
    result = short_case1_run(named(robot, name), "cfc", DURATION_S)
    assert result.metadata["plant"] == name
    text = report_md(result)
    assert "<" not in text
    table = [line for line in text.splitlines() if line.startswith("|")]
    assert len(table) == 3 and all(table_columns(line) == len(TABLE_COLUMNS) for line in table)
    plain = report_md(dataclasses.replace(result, metadata={**result.metadata, "plant": "plain"}))
    lines, plain_lines = text.splitlines(), plain.splitlines()
    assert len(lines) == len(plain_lines)
    differ = [(a, b) for a, b in zip(lines, plain_lines, strict=True) if a != b]
    assert len(differ) == 1 and "(robot plain)" in differ[0][1]
    assert differ[0][0] == differ[0][1].replace("(robot plain)", f"(robot {md_text(name)})")
    assert escape(name) in unescape_markdown(differ[0][0])


def test_the_report_command_escapes_the_folder_of_the_issue(
    robot: Robot, plain: Elements, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``vgtarm report "<a run folder named <img src=x onerror=alert(1)>>" --out page``: the page
    shows the folder's name in its note, its table and its labels, and has no img element."""
    folder = saved_run(robot, tmp_path / "<a run folder named <img src=x onerror=alert(1)>>")
    assert cli.main(["report", str(folder), "--out", str(tmp_path / "page"), "--title", "<b>runs</b>"]) == 0
    page = (tmp_path / "page" / "report.html").read_text("utf-8")
    parsed = elements_of(page)
    assert [t for t, _ in parsed.elements if t == "img"] == []
    assert [t for t, _ in parsed.elements if t == "strong"] == ["strong"]  # the page's own: the robot's name
    assert "".join(parsed.text["title"]) == "<b>runs</b>"
    assert f"Runs: {folder.name}" in "".join(parsed.text["p"])
    assert folder.name + "/" in parsed.text["a"]  # the table's folder cell: a link to the run


def test_a_saved_run_whose_case_is_not_a_number_is_refused_in_one_line(robot: Robot, tmp_path: Path) -> None:
    folder = saved_run(robot, tmp_path / "run")
    summary = folder / "summary.json"
    summary.write_text(summary.read_text("utf-8").replace('"case": 1', '"case": "<script>"'), "utf-8")
    with pytest.raises(InputError, match=r"run folder .*run: case = '<script>': expected a whole number"):
        load_runs([folder])


# -- figures: a "$" starts no math -----------------------------------------------------------


def test_drawing_and_animation_titles_of_a_hostile_robot_draw_as_written(robot: Robot, tmp_path: Path) -> None:
    from vgtarm.app.pictures.animation import animation_frame
    from vgtarm.app.pictures.drawing import pose_figure
    from vgtarm.app.pictures.plotting import label_of, save_figure

    name = r"a $\frac$ robot <script>"  # Matplotlib's math would fail to parse it
    hostile_robot = named(robot, name)
    fig = pose_figure(hostile_robot, robot.parameters.home, dpi=40)
    save_figure(fig, tmp_path / "pose.png")
    assert fig.get_suptitle().startswith(mpl_text(name))
    run = short_case1_run(hostile_robot, "cfc", DURATION_S)
    run = dataclasses.replace(run, metadata={**run.metadata, "controller": "$\\x$"})
    assert label_of(run) == "\\$\\X\\$"
    pixels, _ = animation_frame(hostile_robot, run, 0.02, dpi=30)
    assert pixels.size > 0


def test_draw_command_of_a_robot_named_with_math_writes_its_picture(tmp_path: Path) -> None:
    from importlib import resources

    text = resources.files("vgtarm.model.data").joinpath("reference_robot.toml").read_text("utf-8")
    line = next(line for line in text.splitlines() if line.startswith("name = "))
    config = tmp_path / "robot.toml"
    config.write_text(text.replace(line, 'name = "a $\\\\frac$ b <script>alert(1)</script>"'), "utf-8")
    assert cli.main(["draw", "--config", str(config), "--out", str(tmp_path / "robot.png")]) == 0
    assert (tmp_path / "robot.png").stat().st_size > 1000


# -- a study's report ---------------------------------------------------------------------


@pytest.mark.parametrize("text", HOSTILE[:7] + ("$\\frac$",))
def test_study_report_of_hostile_rows_keeps_its_tables(tmp_path: Path, text: str) -> None:
    """Controllers, ids and error messages of a study's table (a file users can write) stay inside
    their cells of report.md, add no raw ``<``, and draw in the figures as written."""
    from vgtarm.study.report import write_report
    from vgtarm.study.store import Store

    figures = dict.fromkeys(("max_tip_error_m", "max_tip_error_after_transient_m", "rms_tip_error_m"), 1e-4)
    rows: list[dict[str, Any]] = [
        {"id": "a1", "controller": "cfc", "seed": 0, "success": True, "error": "", "message": "completed",
         **figures, "peak_force_n": 10.0},
        {"id": "a2", "controller": text, "seed": 1, "success": True, "error": "", "message": "completed",
         **figures, "peak_force_n": 12.0},
        {"id": text, "controller": text, "seed": 2, "success": False, "error": text, "message": text,
         **dict.fromkeys(figures), "peak_force_n": None},
    ]  # fmt: skip
    store = Store(tmp_path)
    store.prepare()
    store.write_tables(rows)
    report = write_report(tmp_path).read_text("utf-8")
    assert "<" not in report.replace("`<id>.json`", "")  # the report's own code span
    tables = [line for line in report.splitlines() if line.startswith("|")]
    assert len(tables) == 4 * 4 + 3
    for line in tables:
        assert table_columns(line) in (8, 5), line
    failed = tables[-1]
    assert table_columns(failed) == 5 and unescape_markdown(failed).count(escape(text)) >= 3
    assert (tmp_path / "study_error_distribution.png").stat().st_size > 1000


# -- the page in a real browser --------------------------------------------------------------


def test_hostile_page_in_a_real_browser_shows_the_names_and_runs_nothing(robot: Robot, tmp_path: Path) -> None:
    """Headless Chromium: no dialog, no error, no element of the names; the legend and a plot's
    title show the run's label as written (Plotly reads the character references as characters)."""
    from tests.test_html_report import browser_tab
    from vgtarm.app.reports.html import write_html_report

    name = "<script>alert(1)</script> {{x}} %{y} &amp; <b>b</b>"
    hostile_robot = named(robot, name)
    folder = saved_run(hostile_robot, tmp_path / "<img src=x onerror=alert(2)> %{y} {x} &lt;", controller="<b>x")
    runs = load_runs([folder])
    page = write_html_report(hostile_robot, runs, tmp_path / "page", title=name, intro=f"Runs: {folder.name}",
                             max_points=MAX_POINTS, max_frames=MAX_FRAMES)  # fmt: skip
    with browser_tab(page, 4) as (tab, problems):  # a dialog (alert) is one of its problems
        seen = tab.evaluate(
            """() => ({
                images: document.querySelectorAll('img').length,
                scripts: document.querySelectorAll('script').length,
                bold: Array.from(document.querySelectorAll('strong')).map(b => b.textContent),
                title: document.title,
                legend: Array.from(document.querySelectorAll('#paths .legendtext')).map(t => t.textContent),
                heading: document.querySelector('#mechanism-1 .gtitle').textContent,
            })"""
        )
        tab.wait_for_timeout(300)
    assert seen["images"] == 0 and seen["scripts"] == 2 + 4  # Plotly's config and plotly.js, one per plot
    assert seen["bold"] == [name] and seen["title"] == name
    label = runs[0].label
    assert seen["legend"] == ["case 1: desired", label]
    assert seen["heading"].startswith(label + ": t = ")
    assert not problems, problems
