"""The trade-off of issue 22 drawn from a study: max tip error against RMS leg force and chatter.

``python -m vgtarm.app.reports.force_front RUNS_DIR`` reads a study's ``results.csv`` (``vgtarm study
run``), keeps the successful runs, marks the non-dominated ones (no other run has a smaller max tip
error and a smaller RMS force, or chatter) and writes ``front.md`` (every run, front marked) and
``front.png`` (the two fronts) beside it.
"""

from __future__ import annotations

import csv
import sys
from collections.abc import Sequence
from pathlib import Path

#: The run's inputs shown beside the figures.
SETTINGS = (
    "criterion",
    "joint_limit_weight",
    "estimator",
    "estimator_bandwidth_hz",
    "observer_gain",
    "tool_force_feedforward",
    "kp",
    "kv",
    "seed",
)


def pareto(points: Sequence[tuple[float, float]]) -> list[bool]:
    """Whether each (x, y) is non-dominated (no other point at most as large in both and smaller in one)."""
    return [
        not any(a <= x and b <= y and (a < x or b < y) for j, (a, b) in enumerate(points) if j != i)
        for i, (x, y) in enumerate(points)
    ]


def read_runs(folder: Path) -> list[dict[str, str]]:
    """The successful rows of ``folder/results.csv``."""
    with (folder / "results.csv").open(newline="") as handle:
        return [row for row in csv.DictReader(handle) if row.get("success") == "True"]


def front_table(rows: list[dict[str, str]]) -> str:
    """Markdown table of the runs, by max tip error, with their place on the two fronts."""
    error = [float(r["max_tip_error_m"]) * 1e3 for r in rows]
    on_rms = pareto(list(zip(error, (float(r["rms_force_n"]) for r in rows), strict=True)))
    on_chatter = pareto(list(zip(error, (float(r["chatter_n"]) for r in rows), strict=True)))
    head = [*SETTINGS, "max tip error (mm)", "RMS leg force (N)", "peak (N)", "chatter (N)", "front"]
    lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for i in sorted(range(len(rows)), key=lambda i: error[i]):
        r = rows[i]
        front = ", ".join(name for name, on in (("RMS", on_rms[i]), ("chatter", on_chatter[i])) if on)
        cells = [r.get(key) or "" for key in SETTINGS]
        cells += [f"{error[i]:.4f}", f"{float(r['rms_force_n']):.2f}", f"{float(r['peak_force_n']):.1f}"]
        cells += [f"{float(r['chatter_n']):.2f}", front]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def front_figure(rows: list[dict[str, str]], out: Path) -> None:
    """The runs and their fronts: max tip error against RMS leg force and against chatter."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    error = [float(r["max_tip_error_m"]) * 1e3 for r in rows]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, key, label in ((axes[0], "rms_force_n", "RMS leg force (N)"), (axes[1], "chatter_n", "chatter (N)")):
        y = [float(r[key]) for r in rows]
        on = pareto(list(zip(error, y, strict=True)))
        for estimator, marker in (("difference", "o"), ("kalman", "s")):
            pick = [i for i, r in enumerate(rows) if (r.get("estimator") or "difference") == estimator]
            ax.scatter([error[i] for i in pick], [y[i] for i in pick], marker=marker, label=estimator, alpha=0.7)
        front = sorted((error[i], y[i]) for i in range(len(rows)) if on[i])
        ax.plot([p[0] for p in front], [p[1] for p in front], "k-", lw=1, label="front")
        ax.set_xscale("log")
        ax.set_xlabel("max tip error (mm)")
        ax.set_ylabel(label)
        ax.legend()
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    plt.close(fig)


def main(argv: Sequence[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) != 1:
        print("usage: python -m vgtarm.app.reports.force_front RUNS_DIR", file=sys.stderr)
        return 2
    folder = Path(args[0])
    rows = read_runs(folder)
    (folder / "front.md").write_text(front_table(rows))
    front_figure(rows, folder / "front.png")
    print(f"{len(rows)} runs: {folder / 'front.md'}, {folder / 'front.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
