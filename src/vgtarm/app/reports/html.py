"""``report.html``: the report on one interactive page that opens from disk, written with Plotly.

The page is ``report.md`` itself (:mod:`.markdown_html` converts the one Markdown text, so both
hold the same sections under the same headings: the comparison table, the figures, the reading,
the section beyond the paper and what bounds the remaining error), each run linked to its folder
and its ``summary.json``, and, under "Figures", zoomable plots of the tip error and of every
actuator's effort (grouped per module; a menu chooses the run when there are several), the
desired and actual tip paths in 3-D, and the mechanism animated along the first run of each case
study, with a time slider and a play button. ``vgtarm report`` writes the same page for saved runs
from a Markdown text of its own (:func:`runs_markdown`: the title, the table, the figures).

One self-contained file that opens from disk with no server, network or file beside it: Plotly's
own writer (:func:`plotly.io.to_html`) writes each figure, plotly.js inlined once before the first;
the report's PNG figures are inlined as ``data:`` images. Light enough to open at once: every
time series is decimated for display by :func:`decimate_min_max`, which keeps the smallest and the
largest sample of each bucket, so peaks (the maximum error) survive.

Users name things on the page: the runs' folders, the robot, the joints, the title, and a saved
run's metadata (its controller). Every such string goes through :mod:`vgtarm.markup`: into the
Markdown by :func:`~vgtarm.markup.md_text` (then the converter writes every character through
:func:`~vgtarm.markup.html_text`), into the figures by :func:`~vgtarm.markup.plotly_text` (Plotly
reads tags and ``%{...}`` in its labels), into links percent-encoded by
:func:`~vgtarm.markup.url_path`, so it shows as written and adds no element, attribute or link;
``intro`` and ``title`` are plain text too.
"""

from __future__ import annotations

import base64
import json
import os
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ... import checks, errors
from ...errors import InputError
from ...fileio import atomic_write_text
from ...markup import html_text, md_cell, md_text, plotly_text
from ...model.robot import Robot
from ...simulation.result import MODE_GA, SimulationResult
from ..pictures.animation import check_same_robot
from ..pictures.drawing import CLOSENESS_COLOURS, MM
from ..pictures.geometry import MechanismGeometry, mechanism_geometries
from ..pictures.plotting import joint_groups, spans_decades
from .markdown_html import headings, to_html
from .runs import TABLE_COLUMNS, RunSpec, folder_cell, table_row

Array = NDArray[np.float64]

#: Name of the plotly.js file that pages before the self-contained ones loaded from their folder
#: (a folder of such a page, holding it, may still be replaced by a new page).
PLOTLY_JS = "plotly.min.js"
#: Largest number of points of one displayed time series.
MAX_POINTS = 1200
#: Largest number of frames of one mechanism animation.
MAX_FRAMES = 90
#: Colours of the runs (Plotly's default sequence).
COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf")
#: Dash patterns taken in turn once the colours are used up, so no two runs of a figure look alike
#: (``vgtarm reproduce`` draws twelve runs).
DASHES = ("solid", "dash", "dot", "dashdot")
#: Colour scale of the legs' closeness to a limit (as the Matplotlib drawing: green to red).
CLOSENESS_SCALE = [[i / (len(CLOSENESS_COLOURS) - 1), c] for i, c in enumerate(CLOSENESS_COLOURS)]
_COLOURBAR_TITLE = "legs: closeness<br>to a limit<br>(0 mid-range,<br>1 at a limit)"
#: Height of one panel of the efforts' figure (px): one panel per module and one for the twists.
EFFORT_PANEL_PX = 190


def run_line(i: int, width: float) -> dict[str, Any]:
    """The line of the ``i``-th run of a figure: a colour of :data:`COLOURS`, then the next dash."""
    return {"color": COLOURS[i % len(COLOURS)], "dash": DASHES[(i // len(COLOURS)) % len(DASHES)], "width": width}


@dataclass(frozen=True)
class ReportRun:
    """One run on the page: its table cells' spec, its legend label and the folder it is saved in
    (plain text: the page escapes them)."""

    spec: RunSpec
    label: str
    folder: str
    result: SimulationResult
    #: The run's folder as the page links it: relative to the page's folder, or absolute (then
    #: made relative to it); empty for ``folder``.
    path: str = ""

    def __post_init__(self) -> None:
        if not self.path:
            object.__setattr__(self, "path", self.folder)


def spec_of(result: SimulationResult) -> RunSpec:
    """The :class:`RunSpec` of a run from its metadata (case 0 when the run is not a case study, named
    by its path: ``path``, else the reference's name); a case that is not a whole number is refused
    (:class:`~vgtarm.errors.InputError`)."""
    meta = result.metadata
    case = meta.get("case", 0) or 0
    try:
        number = int(case)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"case = {errors.shown(case)}: expected a whole number (a case study) or 0") from None
    return RunSpec(
        case=number,
        controller=str(meta.get("controller", "run")),
        external_force=bool(meta.get("external_force", False)),
        rates=str(meta.get("reference_rates", "exact")),
        name="" if number else str(meta.get("path") or meta.get("reference") or ""),
    )


def decimate_min_max(t: ArrayLike, y: ArrayLike, max_points: int = MAX_POINTS) -> NDArray[np.int64]:
    """Indices of at most ``max_points`` samples of ``y`` (N,) that keep its shape for display.

    The samples are cut into ``max_points // 2`` buckets of consecutive samples; each gives the
    index of its smallest and of its largest finite value, in time order. The first and last
    samples are always kept. ``t`` (N,) only fixes the length. Returns sorted unique indices.
    """
    ta, ya = np.asarray(t, dtype=float), np.asarray(y, dtype=float)
    if ta.shape != ya.shape or ta.ndim != 1:
        raise InputError(f"t and y must be 1-D of one length, got shapes {ta.shape} and {ya.shape}")
    checks.whole("max_points", max_points, 4)
    n = len(ya)
    if n <= max_points:
        return np.arange(n)
    buckets = (max_points - 2) // 2
    # bucket k holds samples edges[k] .. edges[k + 1] - 1, at least 2 of them as n > max_points
    edges = np.linspace(1, n - 1, buckets + 1).astype(np.int64)
    inner = ya[edges[0] : edges[-1]]
    starts = edges[:-1] - edges[0]
    bucket = np.repeat(np.arange(buckets), np.diff(edges))
    index = np.arange(edges[0], edges[-1])
    finite = np.isfinite(inner)  # non-finite samples never count (as NaN for nanargmin/nanargmax)
    low, high = np.where(finite, inner, np.inf), np.where(finite, inner, -np.inf)
    smallest, largest = np.minimum.reduceat(low, starts), np.maximum.reduceat(high, starts)
    # the first index of each bucket's extreme: the smallest index whose value equals it
    first_min = np.minimum.reduceat(np.where(low == smallest[bucket], index, n), starts)
    first_max = np.minimum.reduceat(np.where(high == largest[bucket], index, n), starts)
    known = np.isfinite(smallest)  # a bucket of only non-finite samples gives nothing
    keep = np.concatenate(([0, n - 1], first_min[known], first_max[known]))
    return np.unique(keep.astype(np.int64))


def _series(result: SimulationResult, y: Array, max_points: int) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    n = result.completed
    index = decimate_min_max(result.t[:n], y[:n], max_points)
    return result.t[index].astype(np.float32), y[index].astype(np.float32)


def typed_array(values: ArrayLike, dtype: type[np.floating[Any]] = np.float32) -> dict[str, str]:
    """``values`` as a plotly.js typed array (``{"dtype": "f4", "bdata": <base64>}``, little-endian),
    the form in which Plotly writes a NumPy array into a page."""
    array = np.ascontiguousarray(values, dtype=np.dtype(dtype).newbyteorder("<")).ravel()
    return {"dtype": f"f{array.itemsize}", "bdata": base64.b64encode(array.tobytes()).decode("ascii")}


def _template(name: str = "plotly_white") -> dict[str, Any]:
    """The layout template ``name`` as Plotly writes it into a figure."""
    import plotly.io as pio

    return dict(pio.templates[name].to_plotly_json())


def _layout(layout: dict[str, Any]) -> dict[str, Any]:
    """A figure's layout with Plotly's ``plotly_white`` template, ready for the page.

    The page's figures are plain dicts, written without Plotly's per-property validation (most of
    the page's time went there); :func:`figure_errors` checks them with that validation."""
    return {"template": _template(), **layout}


def figure_errors(figure: dict[str, Any]) -> list[str]:
    """Where Plotly's validation would change the figure ``figure`` (a dict of the page): the paths
    of the entries that differ between it and ``plotly.graph_objects.Figure(figure)``; empty when
    the figure is valid as written. For tests: it costs what the dicts save."""
    import plotly.graph_objects as go
    import plotly.io as pio

    written = json.loads(pio.to_json(figure, validate=False))
    validated = json.loads(pio.to_json(go.Figure(figure), validate=False))
    return _differences(written, validated, "figure")


def _differences(a: Any, b: Any, where: str) -> list[str]:
    if isinstance(a, dict) and isinstance(b, dict):
        keys = sorted(set(a) | set(b))
        return [d for k in keys for d in _differences(a.get(k, "<missing>"), b.get(k, "<missing>"), f"{where}.{k}")]
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [d for i, (x, y) in enumerate(zip(a, b, strict=True)) for d in _differences(x, y, f"{where}[{i}]")]
    return [] if a == b else [f"{where}: {errors.cut(repr(a))} written, {errors.cut(repr(b))} validated"]


def _error_figure(runs: Sequence[ReportRun], max_points: int) -> dict[str, Any]:
    data = []
    for i, run in enumerate(runs):
        t, e = _series(run.result, run.result.tip_error * MM, max_points)
        label = plotly_text(run.label)
        data.append(
            {"type": "scatter", "x": typed_array(t), "y": typed_array(e), "name": label, "mode": "lines",
             "line": run_line(i, 1.2)}
        )  # fmt: skip
    log = spans_decades([run.result.tip_error[: run.result.completed] for run in runs])
    yaxis: dict[str, Any] = {"title": {"text": "tip error (mm)" + (", log scale" if log else "")}}
    yaxis.update({"type": "log", "exponentformat": "power"} if log else {"rangemode": "tozero"})
    layout = _layout(
        {
            "title": {"text": "Tip error |P(q_d) - P(q)| (click a legend entry to hide or show a run; drag to zoom)"},
            "xaxis": {"title": {"text": "time (s)"}},
            "yaxis": yaxis,
            "height": 480,
            "legend": {"font": {"size": 10}},
        }
    )
    return {"data": data, "layout": layout}


def effort_unit(joint: str) -> str:
    """Unit of the effort of the joint named ``joint``: N m for a twist (``psi...``), N for a leg."""
    return "N m" if joint.startswith("psi") else "N"


def _effort_figure(runs: Sequence[ReportRun], max_points: int) -> dict[str, Any]:
    """One panel per module's legs and one for the twists (:func:`joint_groups`), a colour per joint
    of a panel; with several runs a menu chooses the run shown (all of them at once would be
    runs x joints lines)."""
    from plotly.subplots import make_subplots

    names = runs[0].result.joint_names  # every run has them (checked by page_figures)
    groups = joint_groups(names)
    # the panels' axes as Plotly's subplots lay them out (a figure without traces is cheap to build)
    # gaps of 4 % of the height, but never more than half of it in all (Plotly refuses gaps above
    # 1 / (rows - 1): a 30-module arm has 31 panels)
    spacing = min(0.04, 0.5 / max(1, len(groups) - 1))
    grid = make_subplots(rows=len(groups), cols=1, shared_xaxes=True, vertical_spacing=spacing)
    for g, (title, joints) in enumerate(groups):
        unit = effort_unit(names[joints[0]])
        grid.update_yaxes(title_text=f"{plotly_text(title)} ({unit})", title_font={"size": 11}, row=g + 1, col=1)
    grid.update_xaxes(title_text="time (s)", row=len(groups), col=1)
    axes = grid.to_plotly_json()["layout"]
    data = []
    owner: list[int] = []
    for i, run in enumerate(runs):
        label = plotly_text(run.label)
        for g, (_, joints) in enumerate(groups):
            suffix = "" if g == 0 else str(g + 1)
            for k, j in enumerate(joints):
                t, f = _series(run.result, run.result.effort[:, j], max_points)
                joint = plotly_text(names[j])
                hover = f"{joint}: %{{y:.4g}} {effort_unit(names[j])}<extra>{label}</extra>"
                data.append(
                    {"type": "scatter", "x": typed_array(t), "y": typed_array(f), "name": joint,
                     "legendgroup": f"panel {g + 1}", "legendgrouptitle": {"text": plotly_text(groups[g][0])},
                     "visible": i == 0, "mode": "lines",
                     "line": {"color": COLOURS[k % len(COLOURS)], "width": 1.0}, "xaxis": "x" + suffix,
                     "yaxis": "y" + suffix, "hovertemplate": hover}
                )  # fmt: skip
                owner.append(i)
    layout = _layout(
        {
            **{key: value for key, value in axes.items() if key != "template"},
            "title": {
                "text": "Actuator efforts, one panel per module"
                + (" (the menu chooses the run)" if len(runs) > 1 else f": {plotly_text(runs[0].label)}")
            },
            "height": EFFORT_PANEL_PX * len(groups) + 140,
            "legend": {"font": {"size": 10}, "groupclick": "toggleitem", "tracegroupgap": 6},
        }
    )
    if len(runs) > 1:
        layout["updatemenus"] = [
            {
                "type": "dropdown",
                "x": 0.0,
                "xanchor": "left",
                "y": 1.0,
                "yanchor": "bottom",
                "pad": {"b": 8},
                "active": 0,
                "buttons": [
                    {"label": plotly_text(run.label), "method": "restyle",
                     "args": [{"visible": [o == i for o in owner]}]}
                    for i, run in enumerate(runs)
                ],
            }
        ]  # fmt: skip
    return {"data": data, "layout": layout}


def _path_figure(runs: Sequence[ReportRun], max_points: int) -> dict[str, Any]:
    data: list[dict[str, Any]] = []
    shown_desired: set[tuple[int, str]] = set()
    for i, run in enumerate(runs):
        r = run.result
        n = r.completed
        index = decimate_min_max(r.t[:n], r.tip_error[:n], max_points)
        if (run.spec.case, run.spec.name) not in shown_desired:
            shown_desired.add((run.spec.case, run.spec.name))
            d = (r.tip_desired[index] * MM).astype(np.float32)
            name = f"case {run.spec.case}: desired" if run.spec.case else f"{plotly_text(run.label)}: desired"
            data.append(
                {"type": "scatter3d", **_xyz(d), "name": name, "mode": "lines",
                 "line": {"color": "black", "width": 3}}
            )  # fmt: skip
        a = (r.tip[index] * MM).astype(np.float32)
        data.append(
            {"type": "scatter3d", **_xyz(a), "name": plotly_text(run.label), "mode": "lines",
             "line": run_line(i, 2)}
        )  # fmt: skip
    layout = _layout(
        {
            "title": {"text": "Desired and actual tip paths (mm; drag to rotate)"},
            "scene": {
                "xaxis": {"title": {"text": "x (mm)"}},
                "yaxis": {"title": {"text": "y (mm)"}},
                "zaxis": {"title": {"text": "z (mm)"}},
                "aspectmode": "data",
            },
            "height": 620,
            "legend": {"font": {"size": 10}},
        }
    )
    return {"data": data, "layout": layout}


def _xyz(points: NDArray[np.floating[Any]], dtype: type[np.floating[Any]] = np.float32) -> dict[str, dict[str, str]]:
    """``x``, ``y``, ``z`` of a trace from points (M, 3), as typed arrays."""
    return {axis: typed_array(points[:, k], dtype) for k, axis in enumerate("xyz")}


def _polylines(pairs: Sequence[tuple[Array, Array]]) -> tuple[list[float | None], ...]:
    """x, y, z lists (mm) of segments separated by gaps (None)."""
    xs: list[float | None] = []
    ys: list[float | None] = []
    zs: list[float | None] = []
    for start, end in pairs:
        for point in (start * MM, end * MM):
            xs.append(float(point[0]))
            ys.append(float(point[1]))
            zs.append(float(point[2]))
        xs.append(None)
        ys.append(None)
        zs.append(None)
    return xs, ys, zs


def mechanism_traces(geometry: MechanismGeometry) -> list[dict[str, Any]]:
    """The moving traces of the mechanism at one configuration, as Plotly trace dicts (mm).

    Order: legs (coloured by closeness), bars (bases, platforms' top edges, twist parts, tool),
    twist axes, twists' and end-effector's bars, plates, frames' u1, u2, u3 axes, tip. The legs'
    trace carries ``customdata`` with the leg names. The traces are the same for every
    configuration of one robot (a robot without twist joints has an empty twist-axis trace).
    """
    legs = geometry.of_kind("leg")
    lx, ly, lz = _polylines([(s.start, s.end) for s in legs])
    colour: list[float] = []
    for s in legs:
        colour += [float(s.closeness or 0.0)] * 3
    bars = (
        geometry.of_kind("base") + geometry.of_kind("platform") + geometry.of_kind("twist") + geometry.of_kind("tool")
    )
    bx, by, bz = _polylines([(s.start, s.end) for s in bars])
    ax_, ay, az = _polylines([(axis.start, axis.end) for axis in geometry.of_kind("twist_axis")])
    twist_bars = geometry.of_kind("twist_bar")
    ex, ey, ez = _polylines([(bar.start, bar.end) for bar in (*twist_bars, geometry.segment("end_effector"))])
    bar_name = "twists and end-effector" if twist_bars else "end-effector (twist)"
    bar_names = ", ".join(["bases, platforms", *(["twist parts"] if geometry.of_kind("twist") else []), "tool"])
    axis_name = "twist axes" if len(geometry.of_kind("twist_axis")) > 1 else "twist axis"
    vertices = np.concatenate([p.vertices for p in geometry.plates]) * MM
    i_, j_, k_ = [], [], []
    offset = 0
    for plate in geometry.plates:  # fan triangulation of each convex polygon
        for m in range(1, len(plate.vertices) - 1):
            i_.append(offset)
            j_.append(offset + m)
            k_.append(offset + m + 1)
        offset += len(plate.vertices)
    traces: list[dict[str, Any]] = [
        {
            "type": "scatter3d",
            "mode": "lines",
            "name": "legs",
            "showlegend": False,  # a legend entry of a line coloured by values draws wrongly; the colour bar names it
            "x": lx,
            "y": ly,
            "z": lz,
            "customdata": [s.name for s in legs for _ in range(3)],
            "line": {
                "width": 9,
                "color": colour,
                "colorscale": CLOSENESS_SCALE,
                "cmin": 0.0,
                "cmax": 1.0,
                "showscale": True,
                "colorbar": {"title": {"text": _COLOURBAR_TITLE}, "len": 0.6},
            },
            "hoverinfo": "skip",
        },
        {"type": "scatter3d", "mode": "lines", "name": bar_names, "x": bx, "y": by, "z": bz,
         "line": {"width": 7, "color": "#333333"}, "hoverinfo": "skip"},
        {"type": "scatter3d", "mode": "lines", "name": axis_name, "x": ax_, "y": ay, "z": az,
         "line": {"width": 2, "color": "#777777", "dash": "dash"}, "hoverinfo": "skip"},
        {"type": "scatter3d", "mode": "lines", "name": bar_name, "x": ex, "y": ey, "z": ez,
         "line": {"width": 8, "color": "#6a3d9a"}, "hoverinfo": "skip"},
        {"type": "mesh3d", "name": "plates", **_xyz(vertices, np.float64),
         "i": i_, "j": j_, "k": k_, "color": "#6baed6", "opacity": 0.35, "hoverinfo": "skip"},
    ]  # fmt: skip
    frames = f"{geometry.frames[0].label}-{geometry.frames[-1].label}"
    for i, colour_name in enumerate(("#d62728", "#2ca02c", "#1f77b4")):
        fx, fy, fz = _polylines(
            [(f.origin, f.origin + geometry.axis_length * f.rotation[:, i]) for f in geometry.frames]
        )
        traces.append(
            {"type": "scatter3d", "mode": "lines", "name": f"frames {frames}: u{i + 1}", "x": fx, "y": fy, "z": fz,
             "line": {"width": 4, "color": colour_name}, "hoverinfo": "skip"}
        )  # fmt: skip
    tip = geometry.tip * MM
    traces.append(
        {"type": "scatter3d", "mode": "markers", "name": "tip", "x": [tip[0]], "y": [tip[1]], "z": [tip[2]],
         "marker": {"size": 4, "color": "black"}}
    )  # fmt: skip
    return traces


def _status(result: SimulationResult, k: int) -> str:
    text = f"t = {result.t[k]:.3f} s, tip error = {result.tip_error[k] * 1e3:.4f} mm"
    if str(result.metadata.get("controller", "")).lower() == "scm":
        text += ", gains: " + ("GA (switched)" if result.mode[k] == MODE_GA else "fixed")
    return text


def mechanism_figure(
    robot: Robot, run: ReportRun, *, max_frames: int = MAX_FRAMES, fps: float = 10.0
) -> dict[str, Any]:
    """The mechanism along ``run`` with a play button and a time slider (at most ``max_frames``
    frames at evenly spaced completed samples; playing at ``fps`` frames per second)."""
    r = run.result
    n = r.completed
    samples = np.unique(np.linspace(0, n - 1, min(n, max_frames)).round().astype(np.int64))
    geometries = mechanism_geometries(robot, r.q[samples])
    first = mechanism_traces(geometries[0])
    static = _tip_paths(r, n)
    moving = list(range(len(static), len(static) + len(first)))
    label = plotly_text(run.label)
    points = np.concatenate([g.points() for g in geometries]) * MM
    frames = [
        {
            "name": str(i),
            "data": mechanism_traces(g),
            "traces": moving,
            "layout": {"title": {"text": f"{label}: {_status(r, int(k))}"}},
        }
        for i, (g, k) in enumerate(zip(geometries, samples, strict=True))
    ]
    layout = _layout(
        dict(
            title={"text": f"{label}: {_status(r, int(samples[0]))}"},
            height=720,
            scene=_mechanism_scene(points),
            margin={"l": 0, "r": 0, "t": 60, "b": 0},
            legend={"font": {"size": 10}, "x": 0.0, "y": 1.0},
            updatemenus=[_play_buttons(1000.0 / fps)],
            sliders=[_time_slider(r.t, samples)],
        )
    )
    return {"data": [*static, *first], "layout": layout, "frames": frames}


def _tip_paths(r: SimulationResult, n: int) -> list[dict[str, Any]]:
    """The desired and actual tip paths of the first ``n`` samples of ``r`` (mm), decimated for
    display: the animation's traces that do not move."""
    index = decimate_min_max(r.t[:n], r.tip_error[:n], MAX_POINTS)
    d, a = r.tip_desired[index] * MM, r.tip[index] * MM
    return [
        {"type": "scatter3d", **_xyz(d, np.float64), "mode": "lines", "name": "desired tip path",
         "line": {"color": "#1f77b4", "width": 3, "dash": "dash"}, "hoverinfo": "skip"},
        {"type": "scatter3d", **_xyz(a, np.float64), "mode": "lines", "name": "actual tip path",
         "line": {"color": "#ff7f0e", "width": 3}, "hoverinfo": "skip"},
    ]  # fmt: skip


def _mechanism_scene(points: Array) -> dict[str, Any]:
    """The 3-D scene around every drawn point ``points`` (k, 3) (mm), padded by 5 % of the
    largest extent, with equal scales on the three axes."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    pad = 0.05 * float((hi - lo).max())
    return {
        "xaxis": {"title": {"text": "x (mm)"}, "range": [lo[0] - pad, hi[0] + pad]},
        "yaxis": {"title": {"text": "y (mm)"}, "range": [lo[1] - pad, hi[1] + pad]},
        "zaxis": {"title": {"text": "z (mm)"}, "range": [lo[2] - pad, hi[2] + pad]},
        "aspectmode": "manual",
        "aspectratio": dict(zip("xyz", (hi - lo + 2 * pad) / float((hi - lo + 2 * pad).max()), strict=True)),
        "camera": {"eye": {"x": 0.95, "y": -1.05, "z": 0.45}, "center": {"x": 0, "y": 0, "z": -0.05}},
    }


def _play_buttons(step_ms: float) -> dict[str, Any]:
    """The animation's play and pause buttons (a frame every ``step_ms`` milliseconds)."""
    return {
        "type": "buttons",
        "direction": "left",
        "x": 0.0,
        "y": 0.0,
        "xanchor": "left",
        "yanchor": "top",
        "pad": {"t": 40},
        "buttons": [
            {
                "label": "\u25b6 Play",
                "method": "animate",
                "args": [
                    None,
                    {
                        "frame": {"duration": step_ms, "redraw": True},
                        "fromcurrent": True,
                        "transition": {"duration": 0},
                        "mode": "immediate",
                    },
                ],
            },
            {
                "label": "\u275a\u275a Pause",
                "method": "animate",
                "args": [[None], {"frame": {"duration": 0, "redraw": False}, "mode": "immediate"}],
            },
        ],
    }


def _time_slider(t: Array, samples: NDArray[np.int64]) -> dict[str, Any]:
    """The animation's time slider: one step per frame, at the times ``t[samples]`` (s)."""
    return {
        "active": 0,
        "x": 0.16,
        "len": 0.84,
        "y": 0.0,
        "pad": {"t": 30},
        "currentvalue": {"prefix": "t = ", "suffix": " s"},
        "steps": [
            {
                "label": f"{t[k]:.2f}",
                "method": "animate",
                "args": [
                    [str(i)],
                    {
                        "frame": {"duration": 0, "redraw": True},
                        "mode": "immediate",
                        "transition": {"duration": 0},
                    },
                ],
            }
            for i, k in enumerate(samples)
        ],
    }


_STYLE = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 1.5em auto; max-width: 1200px;
       color: #222; padding: 0 1em; line-height: 1.45; }
table { border-collapse: collapse; font-size: 13px; margin: 1em 0; }
th, td { border: 1px solid #ccc; padding: 3px 7px; text-align: right; }
th { background: #f2f2f2; }
td:nth-child(-n+5), td:last-child { text-align: left; }
img { max-width: 100%; height: auto; }
code { font-size: 92%; background: #f4f4f4; padding: 0 2px; }
.plot { margin: 1.5em 0; border-top: 1px solid #ddd; padding-top: 0.5em; }
.note { color: #555; font-size: 13px; }
.caption { font-weight: bold; }
"""
#: The heading of the section that gets the interactive figures (report.md's "Figures").
FIGURES_HEADING = "Figures"
#: A figure file the page embeds: a plain file name of the report's folder.
_FIGURE_FILE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*\.png$")


def page_figures(
    robot: Robot, runs: Sequence[ReportRun], *, max_points: int = MAX_POINTS, max_frames: int = MAX_FRAMES
) -> list[tuple[str, str, dict[str, Any]]]:
    """The page's figures as ``(div id, heading, Plotly figure dict)``: tip error, efforts, 3-D
    paths, then the mechanism along the first run of each case study.

    Every run must have been made with ``robot`` (its joints, and its recorded tip at its first
    sample): else :class:`~vgtarm.errors.InputError` names the run's folder.
    """
    if not runs:
        raise InputError("runs: expected at least one run to report")
    for run in runs:
        try:
            check_same_robot(robot, run.result)
        except InputError as exc:
            raise InputError(f"run {run.folder}: {exc}") from None
    figures: list[tuple[str, str, dict[str, Any]]] = [
        ("tip-error", "Tip error", _error_figure(runs, max_points)),
        ("efforts", "Actuator efforts", _effort_figure(runs, max_points)),
        ("paths", "Tip paths in 3-D", _path_figure(runs, max_points)),
    ]
    animated: set[int] = set()
    for run in runs:  # the first run of each case study
        if run.spec.case in animated:
            continue
        animated.add(run.spec.case)
        figures.append(
            (
                f"mechanism-{len(animated)}",
                f"The mechanism along {run.label}",
                mechanism_figure(robot, run, max_frames=max_frames),
            )
        )
    return figures


def runs_markdown(
    robot: Robot, runs: Sequence[ReportRun], *, title: str = "vgtarm: runs", intro: str = "", base: str | Path = "."
) -> str:
    """The Markdown of a page of saved runs (``vgtarm report``): the title, ``intro``, the table of
    ``report.md`` with each run linked to its folder and summary (relative to ``base``, the page's
    folder) and the heading under which the page puts its figures. Users' strings are escaped."""
    lines = [
        f"# {md_text(title)}",
        "",
        f"{md_text(intro)} Generated on {time.strftime('%Y-%m-%d %H:%M')} for robot"
        f" **{md_text(robot.parameters.name)}**.",
        "",
        "## Maximum tip error",
        "",
        "| " + " | ".join(TABLE_COLUMNS) + " |",
        "|" + " --- |" * len(TABLE_COLUMNS),
    ]
    for run in runs:
        *cells, folder = table_row(run.spec, run.result.summary(), run.folder)
        lines.append("| " + " | ".join(map(md_cell, cells)) + f" | {folder_cell(_relative(run.path, base), folder)} |")
    lines += actuator_markdown([(run.label, run.result.summary()) for run in runs])
    lines += ["", f"## {FIGURES_HEADING}", ""]
    return "\n".join(lines) + "\n"


def actuator_markdown(runs: Sequence[tuple[str, dict[str, Any]]]) -> list[str]:
    """The lines of an "Actuators" section: per run with actuators and per joint with one, the peak
    utilisation of its force limit and the time at a limit (none when no run has actuators). Run
    labels and joint names are escaped."""
    rows = [
        (label, joint, value, summary.get("actuator_time_at_limit_s", {}).get(joint))
        for label, summary in runs
        for joint, value in (summary.get("actuator_peak_utilisation") or {}).items()
    ]
    if not rows:
        return []
    lines = [
        "",
        "## Actuators",
        "",
        "Peak utilisation: the force the actuator delivered over its limit in its direction at the joint's"
        " velocity (at most 1); time at limit: the control periods whose effort was at or beyond that limit.",
        "",
        "| run | joint | peak utilisation | time at limit (s) |",
        "| --- | --- | --- | --- |",
    ]
    for label, joint, value, time_at in rows:
        cells = [label, joint, "" if value is None else f"{value:.3f}", "" if time_at is None else f"{time_at:.3f}"]
        lines.append("| " + " | ".join(map(md_cell, cells)) + " |")
    return lines


def _relative(path: str, base: str | Path) -> str:
    """``path`` (a run's folder) relative to ``base``, with ``/`` between its parts."""
    if not os.path.isabs(path):
        return Path(path).as_posix()
    return Path(os.path.relpath(path, os.path.abspath(base))).as_posix()


def _embedded_image(folder: Path | None) -> Callable[[str, str], str]:
    """The HTML of a figure line of the Markdown: the PNG of ``folder`` inlined (base64), so the page
    needs no file beside it; a name that is not a plain PNG of the folder, or a missing file,
    shows its caption and file name instead."""

    def image(alt: str, name: str) -> str:
        path = None if folder is None or not _FIGURE_FILE.match(name) else folder / name
        if path is None or not path.is_file():
            return f'<p class="note">[{html_text(alt)}: {html_text(name)}]</p>'
        data = base64.b64encode(path.read_bytes()).decode("ascii")
        return f'<p><img src="data:image/png;base64,{data}" alt="{html_text(alt)}"></p>'

    return image


def render_html(
    robot: Robot,
    runs: Sequence[ReportRun],
    *,
    title: str = "vgtarm: runs",
    intro: str = "",
    markdown: str | None = None,
    figures_folder: str | Path | None = None,
    base: str | Path = ".",
    max_points: int = MAX_POINTS,
    max_frames: int = MAX_FRAMES,
) -> str:
    """The page's HTML, one self-contained file: plotly.js inlined once, the figures' PNGs inlined.

    The page is ``markdown`` (``report.md``'s text) converted by :mod:`.markdown_html`, with the
    interactive figures of ``runs`` after its "Figures" heading (appended under one if it has
    none) and the figure files it names read from ``figures_folder``; without ``markdown`` it is
    :func:`runs_markdown` of ``title`` and ``intro`` (plain text, shown as written) with links
    relative to ``base``. ``title`` is also the page's ``<title>``."""
    import plotly.io as pio

    figures = page_figures(robot, runs, max_points=max_points, max_frames=max_frames)
    if markdown is None:
        markdown = runs_markdown(robot, runs, title=title, intro=intro, base=base)
    if FIGURES_HEADING not in [h.text for h in headings(markdown)]:
        markdown += f"\n## {FIGURES_HEADING}\n"
    config = {"displaylogo": False, "responsive": True}
    plots = [
        f'<p class="note">Interactive: drag to zoom or rotate, click a legend entry to hide or show a run. Lengths'
        f" in mm; every curve is decimated for display (at most {max_points} points, keeping each bucket's"
        " extremes).</p>"
    ]
    for k, (div_id, heading, fig) in enumerate(figures):
        body = pio.to_html(
            fig,
            validate=False,
            include_plotlyjs=k == 0,  # plotly.js inlined once, before the first figure
            full_html=False,
            div_id=div_id,
            auto_play=False,
            config=config,
        )
        plots.append(f'<div class="plot"><p class="caption">{html_text(heading)}</p>{body}</div>')
    folder = None if figures_folder is None else Path(figures_folder)
    body_html = to_html(
        markdown,
        image=_embedded_image(folder),
        after_heading={FIGURES_HEADING: "\n".join(plots)},
        first_table_id="summary-table",
    )
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{html_text(title)}</title>",
        f"<style>{_STYLE}</style></head><body>",
        body_html,
        "</body></html>",
    ]
    return "\n".join(parts) + "\n"


def write_html_report(
    robot: Robot,
    runs: Sequence[ReportRun],
    out: str | Path,
    *,
    name: str = "report.html",
    title: str = "vgtarm: runs",
    intro: str = "",
    markdown: str | None = None,
    max_points: int = MAX_POINTS,
    max_frames: int = MAX_FRAMES,
) -> Path:
    """Write the page ``out/name`` (see :func:`render_html`; the figures it names are read from
    ``out``, the runs linked relative to it); returns the page's path."""
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    text = render_html(
        robot,
        runs,
        title=title,
        intro=intro,
        markdown=markdown,
        figures_folder=folder,
        base=folder,
        max_points=max_points,
        max_frames=max_frames,
    )
    return atomic_write_text(folder / name, text)


def load_runs(folders: Sequence[str | Path]) -> list[ReportRun]:
    """Runs saved by :meth:`SimulationResult.save`, labelled from their metadata and folder names."""
    runs = []
    for folder in folders:
        path = Path(folder)
        result = SimulationResult.load(path)
        try:
            spec = spec_of(result)
        except InputError as exc:
            raise InputError(f"run folder {errors.cut(str(path), 200)}: {exc}") from None
        what = f"case {spec.case}" if spec.case else spec.name
        label = f"{what} {spec.label} ({path.name})" if what else f"{path.name}: {spec.label}"
        runs.append(ReportRun(spec=spec, label=label, folder=path.name, result=result, path=os.path.abspath(path)))
    return runs


def runs_from_reproduction(results: dict[RunSpec, SimulationResult]) -> list[ReportRun]:
    """The runs of ``vgtarm reproduce`` with their own specs and folder names."""
    return [
        ReportRun(spec=spec, label=f"case {spec.case} {spec.label}", folder=spec.folder, result=result)
        for spec, result in results.items()
    ]
