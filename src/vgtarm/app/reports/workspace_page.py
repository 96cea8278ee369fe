"""The page of ``vgtarm workspace`` (``workspace.html``): its summary as a Markdown table and the
reachable and dexterous workspaces as one interactive 3-D figure (their boundary points and their
slices, mm), with the figures' PNG files inlined: one self-contained file, as the run report is
(:mod:`.html`: the same style, plotly.js inlined once, the Markdown converted by
:mod:`.markdown_html`; the robot's name, the only text the user wrote, escaped by
:func:`vgtarm.markup.md_text`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ...markup import html_text, md_text
from .html import _STYLE, FIGURES_HEADING, _embedded_image
from .markdown_html import to_html

#: Most boundary points a set draws (evenly thinned beyond: the page stays a few megabytes).
MAX_POINTS = 6000
#: The sets' colours: reachable, then dexterous.
COLOURS = ("#1f77b4", "#d62728")


def workspace_markdown(summary: Mapping[str, Any], pictures: Sequence[str]) -> str:
    """``summary`` (``summary.json``'s data) as the page's Markdown, the ``pictures`` (PNG files of
    the folder) under "Figures"."""
    lines = [f"# Workspace of {md_text(str(summary['robot']))}", ""]
    lines += [
        f"{summary['joints']} joints; the dexterous workspace holds the tool axis within "
        f"{summary['cone_deg']:g} deg of ({', '.join(f'{v:g}' for v in summary['axis'])}); seed {summary['seed']}.",
        "",
        "| set | volume (litres) | Monte Carlo (litres) | difference | voxel (mm) | membership tests |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for name, entry in summary["workspaces"].items():
        check = entry.get("monte_carlo")
        mc = "not run" if check is None else f"{1e3 * check['volume_m3']:.4f} +- {1e3 * check['standard_error_m3']:.4f}"
        relative = None if check is None else check["relative_difference"]
        diff = "" if relative is None else f"{100 * relative:+.2f} %"
        lines.append(
            f"| {name} | {1e3 * entry['volume_m3']:.4f} | {mc} | {diff} | {1e3 * entry['voxel_m']:.1f} |"
            f" {entry['membership_tests']:,} |"
        )
    home = summary["home"]
    distances = ", ".join(f"{md_text(k)} {v:.4f}" for k, v in home["module_distance"].items())
    lines += [
        "",
        "## Dexterity at home",
        "",
        f"Manipulability {home['manipulability']:.6g}, condition number of the tip Jacobian "
        f"{home['condition_number']:.4f}; distance of each module from its flat-truss singularity: {distances}.",
        "",
        f"## {FIGURES_HEADING}",
        "",
    ]
    lines += [f"![{md_text(name)}]({name})\n" for name in pictures]
    return "\n".join(lines) + "\n"


def workspace_figure(volumes: Mapping[str, Any], slices: Mapping[str, Sequence[Any]]) -> dict[str, Any]:
    """The 3-D figure (a Plotly figure as a dict): each set's boundary points (thinned to
    :data:`MAX_POINTS`) and its slices' loops at their heights, in mm."""
    traces: list[dict[str, Any]] = []
    for k, (name, volume) in enumerate(volumes.items()):
        colour = COLOURS[k % len(COLOURS)]
        points = np.asarray(volume.boundary, dtype=float)
        if len(points) > MAX_POINTS:
            points = points[np.linspace(0, len(points) - 1, MAX_POINTS).astype(int)]
        traces.append(
            {
                "type": "scatter3d",
                "mode": "markers",
                "name": f"{name}: boundary",
                "x": (1e3 * points[:, 0]).tolist(),
                "y": (1e3 * points[:, 1]).tolist(),
                "z": (1e3 * points[:, 2]).tolist(),
                "marker": {"size": 1.5, "color": colour, "opacity": 0.35},
            }
        )
        xs: list[float | None] = []
        ys: list[float | None] = []
        zs: list[float | None] = []
        for piece in slices.get(name, ()):
            for loop in piece.loops:
                xs += (1e3 * loop[:, 0]).tolist() + [None]
                ys += (1e3 * loop[:, 1]).tolist() + [None]
                zs += [1e3 * piece.z] * len(loop) + [None]
        traces.append(
            {
                "type": "scatter3d",
                "mode": "lines",
                "name": f"{name}: slices",
                "x": xs,
                "y": ys,
                "z": zs,
                "line": {"color": colour, "width": 4},
            }
        )
    axis = {"title": {"text": ""}}
    layout = {
        "height": 700,
        "margin": {"l": 0, "r": 0, "t": 30, "b": 0},
        "scene": {
            "aspectmode": "data",
            "xaxis": {**axis, "title": {"text": "x (mm)"}},
            "yaxis": {**axis, "title": {"text": "y (mm)"}},
            "zaxis": {**axis, "title": {"text": "z (mm)"}},
        },
        "legend": {"itemsizing": "constant"},
    }
    return {"data": traces, "layout": layout}


def workspace_html(
    summary: Mapping[str, Any],
    volumes: Mapping[str, Any],
    slices: Mapping[str, Sequence[Any]],
    folder: str | Path,
    pictures: Sequence[str],
) -> str:
    """The page's HTML: :func:`workspace_markdown`, the interactive :func:`workspace_figure` after its
    "Figures" heading, the ``pictures`` read from ``folder`` and inlined."""
    import plotly.io as pio

    body = pio.to_html(
        workspace_figure(volumes, slices),
        validate=False,
        include_plotlyjs=True,
        full_html=False,
        div_id="workspace-3d",
        config={"displaylogo": False, "responsive": True},
    )
    plot = (
        '<p class="note">Interactive: drag to rotate, scroll to zoom, click a legend entry to hide or show a'
        f" set. Lengths in mm; at most {MAX_POINTS} boundary points per set.</p>"
        f'<div class="plot"><p class="caption">The workspaces in 3-D</p>{body}</div>'
    )
    markdown = workspace_markdown(summary, pictures)
    body_html = to_html(markdown, image=_embedded_image(Path(folder)), after_heading={FIGURES_HEADING: plot})
    title = f"vgtarm: workspace of {summary['robot']}"
    return (
        "\n".join(
            [
                "<!DOCTYPE html>",
                '<html lang="en"><head><meta charset="utf-8">',
                f"<title>{html_text(title)}</title>",
                f"<style>{_STYLE}</style></head><body>",
                body_html,
                "</body></html>",
            ]
        )
        + "\n"
    )
