"""``vgtarm study report DIR``: means, spreads and worst cases per controller, and figures.

Reads ``results.parquet`` of a study folder and writes ``report.md`` with the table and the
figures: the distribution of the maximum tip error per controller (box plot with every run as a
point), the error against each controller-model factor that the study varies, and against each
gain the study varies.

The table's values come from a file users can write (controllers, ids, error messages that quote
their files): every one goes into the Markdown through :mod:`vgtarm.markup` and into the figures'
labels through :func:`~vgtarm.markup.mpl_text`.
"""

from __future__ import annotations

import fnmatch
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ..errors import InputError
from ..experiment.options import study_options
from ..fileio import atomic_path, atomic_write_text
from ..markup import md_cell, md_code, mpl_text
from .store import FIGURE_FILES, Store, read_table

#: Figures of the table: (column, label, scale to the shown unit).
FIGURES = (
    ("max_tip_error_m", "max tip error (mm)", 1e3),
    ("max_tip_error_after_transient_m", "max after transient (mm)", 1e3),
    ("rms_tip_error_m", "RMS tip error (mm)", 1e3),
    ("peak_force_n", "peak force (N)", 1.0),
)
MODEL_FACTORS = ("model_mass", "model_inertia", "model_friction")


def numeric_inputs() -> tuple[str, ...]:
    """The study's numeric parameters other than the model factors, in declaration order
    (:func:`vgtarm.experiment.options.study_options`): each that varies gets a figure of the
    maximum tip error against it."""
    return tuple(
        name
        for name, declared in study_options().items()
        if declared.kind in (int, float) and name not in MODEL_FACTORS
    )


def group_statistics(rows: Sequence[dict[str, Any]], column: str, by: str = "controller") -> dict[str, dict[str, Any]]:
    """Per value of ``by``: ``n``, ``failed``, and over the successful runs the ``mean``, ``std``
    (sample, ddof 1; NaN for one run), ``min``, ``max`` of ``column`` and the ``worst`` row's id."""
    out: dict[str, dict[str, Any]] = {}
    for key in sorted({str(r[by]) for r in rows}):
        group = [r for r in rows if str(r[by]) == key]
        ok = [r for r in group if r.get("success") and r.get(column) is not None]
        values = np.array([float(r[column]) for r in ok])
        worst = ok[int(np.argmax(values))] if ok else None
        out[key] = {
            "n": len(group),
            "failed": len(group) - sum(1 for r in group if r.get("success")),
            "mean": float(values.mean()) if len(values) else math.nan,
            "std": float(values.std(ddof=1)) if len(values) > 1 else math.nan,
            "min": float(values.min()) if len(values) else math.nan,
            "max": float(values.max()) if len(values) else math.nan,
            "worst": worst,
        }
    return out


def plot_error_distribution(rows: Sequence[dict[str, Any]], *, ax: Axes | None = None) -> Axes:
    """Box plot of the maximum tip error (mm) per controller, every successful run as a point."""
    ax = ax if ax is not None else Figure(figsize=(6, 4), layout="constrained").add_subplot()
    controllers = sorted({str(r["controller"]) for r in rows})
    data = [
        [1e3 * float(r["max_tip_error_m"]) for r in rows if str(r["controller"]) == c and _ok(r, "max_tip_error_m")]
        for c in controllers
    ]
    ax.boxplot(data, showfliers=False)
    ax.set_xticks(range(1, len(controllers) + 1), [mpl_text(c.upper()) for c in controllers])
    jitter = np.random.default_rng(0)  # fixed: the same figure for the same table
    for i, values in enumerate(data, start=1):
        ax.scatter(i + jitter.uniform(-0.12, 0.12, len(values)), values, s=12, alpha=0.6, zorder=3)
    ax.set_ylabel("max tip error (mm)")
    ax.set_title("Maximum tip error per controller")
    ax.grid(True, axis="y", alpha=0.3)
    return ax


def plot_error_against(rows: Sequence[dict[str, Any]], column: str, *, ax: Axes | None = None) -> Axes:
    """The maximum tip error (mm) of each successful run against the input ``column``, per controller."""
    ax = ax if ax is not None else Figure(figsize=(6, 4), layout="constrained").add_subplot()
    for controller in sorted({str(r["controller"]) for r in rows}):
        chosen = [r for r in rows if str(r["controller"]) == controller and _ok(r, "max_tip_error_m")]
        chosen = [r for r in chosen if r.get(column) is not None]
        x = [float(r[column]) for r in chosen]
        y = [1e3 * float(r["max_tip_error_m"]) for r in chosen]
        ax.scatter(x, y, s=14, alpha=0.7, label=mpl_text(controller.upper()))
    ax.set_xlabel(column)
    ax.set_ylabel("max tip error (mm)")
    ax.grid(True, alpha=0.3)
    ax.legend()
    return ax


def varied(rows: Sequence[dict[str, Any]], columns: Sequence[str]) -> list[str]:
    """The columns among ``columns`` that take more than one value in ``rows``."""
    return [c for c in columns if len({r.get(c) for r in rows if r.get(c) is not None}) > 1]


def write_report(folder: str | Path) -> Path:
    """Write ``report.md`` and its figures into the study folder ``folder``; returns the report.

    Each is written atomically, and only over a file vgtarm wrote (listed in the folder's mark,
    :meth:`~vgtarm.study.store.Store.claim`): a ``report.md`` or figure of the user's, or a folder
    vgtarm does not recognise as a study folder, is refused in one line before anything is written."""
    where = Path(folder)
    rows = read_table(where)
    if not rows:
        raise InputError(f"study folder {where}: results.parquet has no runs")
    ok = sum(1 for r in rows if r.get("success"))
    lines = [
        "# Study report",
        "",
        f"Generated by `vgtarm study report` on {time.strftime('%Y-%m-%d')} from `results.parquet`: {len(rows)} runs,"
        f" {ok} completed, {len(rows) - ok} failed. Means and spreads (sample standard deviation) are over the"
        " completed runs; the worst run is named by its id (its file `<id>.json`).",
        "",
    ]
    for column, label, scale in FIGURES:
        stats = group_statistics(rows, column)
        lines += [
            f"## {label}",
            "",
            "| controller | runs | failed | mean | std | min | max | worst run (seed) |",
            "| --- | --- | --- | --- | --- | --- | --- | --- |",
        ]
        for controller, s in stats.items():
            worst = s["worst"]
            where_worst = f"{md_code(worst['id'])} ({md_cell(worst.get('seed'))})" if worst else "—"
            cells = [_fmt(s[k] * scale) for k in ("mean", "std", "min", "max")]
            lines.append(
                f"| {md_cell(controller.upper())} | {s['n']} | {s['failed']} | {' | '.join(cells)} | {where_worst} |"
            )
        lines.append("")
    failed = [r for r in rows if not r.get("success")]
    if failed:
        lines += [
            "## Failed runs",
            "",
            "| id | controller | seed | error | message |",
            "| --- | --- | --- | --- | --- |",
        ]
        for r in failed[:50]:
            cells = [md_code(r["id"]), *(md_cell(r.get(key)) for key in ("controller", "seed", "error"))]
            cells.append(md_cell(r.get("message", "")))
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    lines += ["## Figures", ""]
    figures: list[tuple[str, str, str | None]] = [
        ("Maximum tip error per controller", "study_error_distribution.png", None)
    ]
    figures += [
        (f"Maximum tip error against {c} (controller model error)", f"study_error_vs_{c}.png", c)
        for c in varied(rows, MODEL_FACTORS)
    ]
    figures += [
        (f"Maximum tip error against {c}", f"study_error_vs_{c}.png", c) for c in varied(rows, numeric_inputs())
    ]
    keep = {name for _, name, _ in figures}
    store = Store(where)
    store.claim("report.md", *sorted(keep))  # before anything is written: never over a user's file
    (where / "report.md").unlink(missing_ok=True)  # vgtarm's (claimed): no report of other figures meanwhile
    for stale in sorted((store.listed() or set()) - keep):  # figures of an earlier report against other columns
        if fnmatch.fnmatchcase(stale, FIGURE_FILES):
            store.discard(stale)
    for caption, name, against in figures:
        fig = Figure(figsize=(6.4, 4.2), layout="constrained")
        if against is None:
            plot_error_distribution(rows, ax=fig.add_subplot())
        else:
            plot_error_against(rows, against, ax=fig.add_subplot()).set_title(caption)
        with atomic_path(where / name) as temporary:
            fig.savefig(temporary, dpi=120)
        lines += [f"**{caption}**", "", f"![{caption}]({name})", ""]
    if len(figures) == 1:
        lines += ["(The study varies no controller-model factor and no gain: no figures against them.)", ""]
    return atomic_write_text(where / "report.md", "\n".join(lines))


def _ok(row: dict[str, Any], column: str) -> bool:
    return bool(row.get("success")) and row.get(column) is not None


def _fmt(value: float) -> str:
    return "—" if not math.isfinite(value) else f"{value:.4g}"
