"""The trade-off of issue 22 in the section beyond the paper: max tip error against actuator force.

Case 2 with the tool force, realistic sensing (1 um leg encoders, a controller model 10 % heavy), the
expected cutting force fed forward, seeds 0 to 4, over the redundancy criterion, the state estimate
(differenced velocities, or the Kalman estimate at 100, 120 and 140 Hz), the observer gain and the
gains: the studies ``examples/studies/low-force-front-kalman.toml`` (480 runs) and
``low-force-front-differenced.toml`` (80 runs), about 20 s on two Dask workers. The reproduction does not
rerun them: their per-run figures ship as the small file ``force_study.csv`` beside this module,
written by :func:`summarise` from the study folders (``python -m vgtarm.app.reports.force_study
PRESET_RUNS DIFFERENCE_RUNS``, the folders of ``vgtarm study run``), and the report reads it
(:func:`load_summary`, :func:`section_lines`, :func:`front_figure`). A test runs the preset's point
again and compares it with the file.

Each setting (every input but the seed) is one point: its worst max tip error over the seeds against
its first seed's RMS leg force and chatter (:func:`vgtarm.app.reports.force_front.by_setting`); the
low-force preset is the setting :func:`~vgtarm.app.reports.force_front.choose` picks.
"""

from __future__ import annotations

import csv
import sys
from collections.abc import Iterable, Mapping
from pathlib import Path

from matplotlib.figure import Figure

from ...errors import InputError
from ...fileio import atomic_write_text
from ...markup import md_cell
from .force_front import CHATTER_LIMIT_N, PEAK_LIMIT_N, Setting, by_setting, choose, pareto, read_runs

#: The shipped summary of the studies (one row per run).
SUMMARY_FILE = Path(__file__).with_name("force_study.csv")
#: Its columns: the settings that vary, the seed, and the run's figures (as ``results.csv`` names them).
COLUMNS = (
    "criterion", "estimator", "estimator_bandwidth_hz", "observer_gain", "kp", "kv", "seed",
    "max_tip_error_m", "rms_force_n", "peak_force_n", "chatter_n",
)  # fmt: skip
#: The issue's targets: max tip error (mm), RMS leg force (N); peak and chatter are the rule's limits.
ERROR_TARGET_MM = 0.030
RMS_TARGET_N = 24.0

Row = Mapping[str, str]


def summarise(rows: Iterable[Row]) -> list[dict[str, str]]:
    """The summary's rows from studies' ``results.csv`` rows (successful runs; the figures to 6
    significant digits). A row without one of :data:`COLUMNS` is refused in one line."""
    out = []
    for row in rows:
        missing = [key for key in COLUMNS if key not in row]
        if missing:
            raise InputError(f"results.csv row without {missing[0]!r}: expected the columns {', '.join(COLUMNS)}")
        cells = {key: str(row[key]) for key in COLUMNS}
        for key in ("max_tip_error_m", "rms_force_n", "peak_force_n", "chatter_n"):
            cells[key] = f"{float(cells[key]):.6g}"
        out.append(cells)
    return sorted(out, key=lambda r: tuple(r[k] for k in COLUMNS[:7]))


def write_summary(rows: list[dict[str, str]], path: Path = SUMMARY_FILE) -> None:
    """Write the summary (atomically)."""
    lines = [",".join(COLUMNS)] + [",".join(row[k] for k in COLUMNS) for row in rows]
    atomic_write_text(path, "\n".join(lines) + "\n", "force study summary")


def load_summary(path: Path = SUMMARY_FILE) -> list[dict[str, str]]:
    """The shipped summary (see the module's docstring), rows as ``results.csv`` gives them."""
    with path.open(encoding="utf-8", newline="") as stream:
        return list(csv.DictReader(stream))


def _label(g: Setting) -> str:
    """A setting in words: criterion, estimate, observer gain, gains."""
    bandwidth = g.value("estimator_bandwidth_hz")  # empty: the estimator's default
    estimate = g.value("estimator") + (f" {float(bandwidth):g} Hz" if bandwidth else "")
    gains = f"{float(g.value('kp')):g} / {float(g.value('kv')):g}"
    return f"{g.value('criterion')}, {estimate}, K_O {float(g.value('observer_gain')):g}, {gains}"


def section_lines(rows: list[dict[str, str]], figure: str) -> list[str]:
    """Markdown: what the studies are, the non-dominated settings and the preset's, the figure."""
    groups = by_setting(rows)
    pick = choose(groups)
    errors = [g.worst_mm for g in groups]
    on_rms = pareto(list(zip(errors, (g.rms_n for g in groups), strict=True)))
    on_chatter = pareto(list(zip(errors, (g.chatter_n for g in groups), strict=True)))
    lines = [
        "",
        "### The trade-off: tip error against actuator force (issue 22)",
        "",
        f"Case 2 with the tool force, realistic sensing, the expected cutting force fed forward, seeds 0-4: {len(rows)}"
        f" runs in {len(groups)} settings of criterion, state estimate, observer gain `K_O` and gains `Kp / Kv`."
        " Each setting is a point: its worst max tip error over the seeds against the first seed's RMS leg force"
        " and chatter. Figures from the studies shipped as `force_study.csv` (the reproduction does not rerun"
        " them; `python -m vgtarm.app.reports.force_study` rebuilds the file from the folders of `vgtarm study"
        " run` on `examples/studies/low-force-front-kalman.toml` and `low-force-front-differenced.toml`). Listed: the"
        " settings on either front, and the low-force preset, the least worst error with seed 0's peak at most"
        f" {PEAK_LIMIT_N:g} N and chatter at most {CHATTER_LIMIT_N:g} N.",
        "",
        "| setting | worst max tip error (mm) | seed 0: RMS leg force (N) | peak (N) | chatter (N) | front |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for i, g in enumerate(groups):
        if not (on_rms[i] or on_chatter[i] or i == pick):
            continue
        front = ", ".join(name for name, on in (("RMS", on_rms[i]), ("chatter", on_chatter[i])) if on)
        name = md_cell(_label(g)) + (" **(low-force preset)**" if i == pick else "")
        lines.append(
            f"| {name} | {g.worst_mm:.4f} | {g.rms_n:.2f} | {g.peak_n:.1f} | {g.chatter_n:.2f} | {front or '-'} |"
        )
    least = min(g.rms_n for g in groups)
    lines += [
        "",
        f"The issue's targets: max tip error <= {ERROR_TARGET_MM:g} mm on every seed, RMS leg force <="
        f" {RMS_TARGET_N:g} N, peak <= {PEAK_LIMIT_N:g} N, chatter <= {CHATTER_LIMIT_N:g} N. The least RMS leg force"
        f" of any setting is {least:.2f} N: the load of the reference, which no estimate, gain or feedforward"
        ' removes (`docs/control.md`, "The path-wide version, measured").',
        "",
        f"![tip error against actuator force]({figure})",
    ]
    return lines


def front_figure(rows: list[dict[str, str]]) -> Figure:
    """Per setting, worst max tip error over the seeds against seed 0's RMS leg force and chatter, by
    criterion and estimate; the fronts, the preset and the targets marked."""
    groups = by_setting(rows)
    pick = choose(groups)
    fig = Figure(figsize=(10, 4.2), layout="constrained")
    axes = fig.subplots(1, 2)
    kinds = sorted({(g.value("criterion"), g.value("estimator")) for g in groups})
    for ax, value, label, target in (
        (axes[0], lambda g: g.rms_n, "seed 0: RMS leg force (N)", RMS_TARGET_N),
        (axes[1], lambda g: g.chatter_n, "seed 0: chatter (N)", CHATTER_LIMIT_N),
    ):
        for criterion, estimator in kinds:
            pick_kind = [g for g in groups if (g.value("criterion"), g.value("estimator")) == (criterion, estimator)]
            ax.scatter(
                [g.worst_mm for g in pick_kind],
                [value(g) for g in pick_kind],
                s=14,
                marker="s" if estimator == "kalman" else "o",
                alpha=0.7,
                label=f"{criterion}, {estimator}",
            )
        points = [(g.worst_mm, value(g)) for g in groups]
        front = sorted(p for p, on in zip(points, pareto(points), strict=True) if on)
        ax.plot([p[0] for p in front], [p[1] for p in front], "k-", lw=1, label="front")
        if pick is not None:
            ax.plot(groups[pick].worst_mm, value(groups[pick]), "r*", ms=12, label="low-force preset")
        ax.axvline(ERROR_TARGET_MM, color="0.5", ls="--", lw=0.8)
        ax.axhline(target, color="0.5", ls=":", lw=0.8, label="target")
        ax.set_xlabel("worst max tip error over seeds 0-4 (mm)")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle("Case 2 with the tool force, realistic sensing: tip error against actuator force")
    return fig


def main(argv: list[str] | None = None) -> int:
    """``python -m vgtarm.app.reports.force_study RUNS_DIR [RUNS_DIR ...]``: rewrite the shipped summary."""
    folders = [Path(a) for a in (sys.argv[1:] if argv is None else argv)]
    if not folders:
        print("usage: python -m vgtarm.app.reports.force_study RUNS_DIR [RUNS_DIR ...]", file=sys.stderr)
        return 2
    write_summary(summarise(row for folder in folders for row in read_runs(folder)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
