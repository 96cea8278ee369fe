"""The 60-run study of switching control's safe variant (issue 23) in the section beyond the paper.

Case 2 with the tool force, 1 um leg encoders, controller model mass 0.9, 1.0 and 1.1 times the
plant's, seeds 0-19: safe SCM, paper SCM and CFC on the same runs (180 runs, about 4 minutes on
two workers). The reproduction does not rerun them: the study's per-run figures ship as the small
file ``safe_study.csv`` beside this module, written by :func:`summarise` from the study folders
(``python -m vgtarm.app.reports.safe_study SCM_DIR CFC_DIR``, the folders of ``vgtarm study run``
on ``examples/studies/safe-switching-scm.toml`` and ``safe-switching-cfc.toml``), and the report reads it
(:func:`load_summary`, :func:`section_lines`, :func:`study_figure`).
"""

from __future__ import annotations

import csv
import io
import math
import statistics
import sys
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from ...errors import InputError
from ...fileio import atomic_write_text, read_text_limited

#: The shipped summary of the study (one row per run: model mass and seed).
SUMMARY_FILE = Path(__file__).with_name("safe_study.csv")
COLUMNS = (
    "model_mass", "seed", "safe_max_mm", "safe_activations", "safe_real_time_factor",
    "paper_max_mm", "paper_diverged_s", "cfc_max_mm",
)  # fmt: skip

Row = Mapping[str, Any]


def _key(row: Row) -> tuple[float, int]:
    return float(row["model_mass"]), int(row["seed"])


def summarise(scm_rows: Iterable[Row], cfc_rows: Iterable[Row]) -> list[dict[str, float]]:
    """One row per (model mass, seed) from the study's ``results.csv`` rows: the safe variant's max
    tip error (mm), activations and real-time factor; the paper variant's max error or the time it
    diverged (NaN otherwise); CFC's max error. A missing or failed safe/CFC run is refused."""
    safe: dict[tuple[float, int], Row] = {}
    paper: dict[tuple[float, int], Row] = {}
    for row in scm_rows:
        (safe if row["scm_variant"] == "safe" else paper)[_key(row)] = row
    cfc = {_key(row): row for row in cfc_rows}
    out = []
    for key in sorted(safe):
        s, p, c = safe[key], paper.get(key), cfc.get(key)
        if c is None:
            raise InputError(f"model_mass = {key[0]}, seed = {key[1]}: no CFC run; expected one for every safe run")
        ok = str(p["success"]) == "True" if p is not None else False
        out.append(
            {
                "model_mass": key[0],
                "seed": key[1],
                "safe_max_mm": float(s["max_tip_error_m"]) * 1e3 if str(s["success"]) == "True" else math.nan,
                "safe_activations": float(s["ga_activations"]),
                "safe_real_time_factor": float(s["real_time_factor"]),
                "paper_max_mm": float(p["max_tip_error_m"]) * 1e3 if p is not None and ok else math.nan,
                "paper_diverged_s": math.nan if p is None or ok else float(p["simulated_time_s"]),
                "cfc_max_mm": float(c["max_tip_error_m"]) * 1e3,
            }
        )
    return out


def write_summary(rows: list[dict[str, float]], path: Path = SUMMARY_FILE) -> None:
    stream = io.StringIO()
    writer = csv.DictWriter(stream, fieldnames=COLUMNS)
    writer.writeheader()
    for row in rows:
        writer.writerow({k: f"{row[k]:.6g}" for k in COLUMNS})
    atomic_write_text(path, stream.getvalue(), "safe study summary")  # never a partial file


def load_summary(path: Path = SUMMARY_FILE) -> list[dict[str, float]]:
    """The shipped summary (see the module's docstring)."""
    with path.open(encoding="utf-8") as stream:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(stream)]


def section_lines(rows: list[dict[str, float]], figure: str) -> list[str]:
    """Markdown: the study's table per controller model, its verdict on the issue's targets, the figure."""
    lines = [
        "",
        "### Safe switching control on 60 runs (issue 23)",
        "",
        "Case 2 with the tool force, 1 um leg encoders, controller model mass 0.9 / 1.0 / 1.1 times the"
        " plant's, seeds 0-19; the same runs for each controller. Figures from the study shipped as"
        " `safe_study.csv` (the reproduction does not rerun its 180 runs; `python -m vgtarm.app.reports.safe_study`"
        " rebuilds the file from the folders of `vgtarm study run` on `examples/studies/safe-switching-scm.toml`"
        " and `safe-switching-cfc.toml`).",
        "",
        "| model mass | safe: diverged | safe: median / max of max tip error | safe below CFC | paper: diverged"
        " | CFC: max tip error | safe: activations (median) |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for mass in sorted({r["model_mass"] for r in rows}):
        group = [r for r in rows if r["model_mass"] == mass]
        safe = [r["safe_max_mm"] for r in group]
        below = sum(1 for r in group if r["safe_max_mm"] < r["cfc_max_mm"])
        diverged = [r["paper_diverged_s"] for r in group if not math.isnan(r["paper_diverged_s"])]
        paper = f"{len(diverged)} of {len(group)}" + (f" (from {min(diverged):.3f} s)" if diverged else "")
        lines.append(
            f"| {mass:g} | {sum(math.isnan(x) for x in safe)} of {len(group)} | {statistics.median(safe):.3f} /"
            f" {max(safe):.3f} mm | {below} of {len(group)} | {paper} | {min(r['cfc_max_mm'] for r in group):.3f}"
            f" - {max(r['cfc_max_mm'] for r in group):.3f} mm"
            f" | {statistics.median(r['safe_activations'] for r in group):.0f} |"
        )
    safe_all = [r["safe_max_mm"] for r in rows]
    lines += [
        "",
        f"All {len(rows)} runs: safe diverged {sum(math.isnan(x) for x in safe_all)}, paper diverged"
        f" {sum(not math.isnan(r['paper_diverged_s']) for r in rows)}; the safe variant's max tip error has median"
        f" {statistics.median(safe_all):.3f} mm and max {max(safe_all):.3f} mm (target: median <= 0.30 mm), below"
        f" CFC's on {sum(r['safe_max_mm'] < r['cfc_max_mm'] for r in rows)} of {len(rows)} runs.",
        "",
        f"![safe switching control on 60 runs]({figure})",
    ]
    return lines


def study_figure(rows: list[dict[str, float]]) -> Any:
    """Max tip error per run: safe SCM, paper SCM (where it held; diverged runs marked at the top) and CFC."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3.6))
    x = list(range(len(rows)))
    ax.plot(x, [r["cfc_max_mm"] for r in rows], "s", ms=3, color="0.5", label="CFC")
    ax.plot(x, [r["paper_max_mm"] for r in rows], "^", ms=3, color="tab:red", label="paper SCM (held)")
    top = max(r["cfc_max_mm"] for r in rows) * 1.15
    div = [i for i, r in enumerate(rows) if not math.isnan(r["paper_diverged_s"])]
    ax.plot(div, [top] * len(div), "x", ms=4, color="tab:red", label="paper SCM diverged")
    ax.plot(x, [r["safe_max_mm"] for r in rows], "o", ms=3, color="tab:blue", label="safe SCM")
    ax.axhline(0.30, color="tab:blue", lw=0.8, ls="--", label="target median 0.30 mm")
    for boundary in range(20, len(rows), 20):
        ax.axvline(boundary - 0.5, color="0.8", lw=0.8)
    ax.set_xlabel("run (model mass 0.9, 1.0, 1.1; seeds 0-19 each)")
    ax.set_ylabel("max tip error (mm)")
    ax.set_ylim(0, top * 1.08)
    ax.legend(fontsize=7, ncol=3, loc="lower right")
    fig.tight_layout()
    return fig


def main(argv: list[str] | None = None) -> None:
    """``python -m vgtarm.app.reports.safe_study SCM_DIR CFC_DIR``: rewrite the shipped summary."""
    scm_dir, cfc_dir = (Path(a) for a in (argv if argv is not None else sys.argv[1:]))
    scm, cfc = (read_text_limited(d / "results.csv", what="study results file") for d in (scm_dir, cfc_dir))
    write_summary(summarise(csv.DictReader(io.StringIO(scm)), csv.DictReader(io.StringIO(cfc))))


if __name__ == "__main__":
    main()
