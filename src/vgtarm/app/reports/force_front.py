"""The trade-off of issue 22 drawn from a study: max tip error against RMS leg force and chatter.

``python -m vgtarm.app.reports.force_front RUNS_DIR`` reads a study's ``results.csv`` (``vgtarm study
run``), keeps the successful runs, marks the non-dominated ones (no other run has a smaller max tip
error and a smaller RMS force, or chatter) and writes ``front.md`` (every run, front marked) and
``front.png`` (the two fronts) beside it. A study over seeds also gets, in ``front.md``, a table by
setting (:func:`by_setting`): the worst max tip error over the seeds beside the first seed's force
figures, with the setting that the low-force preset's rule picks (:func:`choose`) marked.
"""

from __future__ import annotations

import csv
import io
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ...fileio import atomic_path, atomic_write_text, read_text_limited
from ...markup import md_cell

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
#: The inputs that make a setting: every one but the seed.
SETTING_KEYS = tuple(key for key in SETTINGS if key != "seed")


def pareto(points: Sequence[tuple[float, float]]) -> list[bool]:
    """Whether each (x, y) is non-dominated (no other point at most as large in both and smaller in one)."""
    return [
        not any(a <= x and b <= y and (a < x or b < y) for j, (a, b) in enumerate(points) if j != i)
        for i, (x, y) in enumerate(points)
    ]


def read_runs(folder: Path) -> list[dict[str, str]]:
    """The successful rows of ``folder/results.csv``."""
    text = read_text_limited(folder / "results.csv", what="study results file")  # a pipe: refused, never waited on
    return [row for row in csv.DictReader(io.StringIO(text, newline="")) if row.get("success") == "True"]


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
        cells = [md_cell(r.get(key) or "") for key in SETTINGS]
        cells += [f"{error[i]:.4f}", f"{float(r['rms_force_n']):.2f}", f"{float(r['peak_force_n']):.1f}"]
        cells += [f"{float(r['chatter_n']):.2f}", front]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


#: The preset's rule (:func:`choose`): the first seed's peak leg force (N) and chatter (N) at most these.
PEAK_LIMIT_N = 80.0
CHATTER_LIMIT_N = 4.0


@dataclass(frozen=True)
class Setting:
    """The runs of one setting (every input but the seed): each seed's max tip error and the force
    figures of the first (lowest) seed."""

    settings: tuple[str, ...]
    seeds: tuple[int, ...]
    errors_mm: tuple[float, ...]
    peak_n: float
    rms_n: float
    chatter_n: float

    @property
    def worst_mm(self) -> float:
        """The largest max tip error over the seeds (mm)."""
        return max(self.errors_mm)

    def value(self, key: str) -> str:
        """The setting's input ``key`` (one of :data:`SETTING_KEYS`), as ``results.csv`` wrote it."""
        return self.settings[SETTING_KEYS.index(key)]


def by_setting(rows: list[dict[str, str]]) -> list[Setting]:
    """The runs grouped by their settings other than the seed, by worst max tip error."""
    groups: dict[tuple[str, ...], list[dict[str, str]]] = {}
    for r in rows:
        groups.setdefault(tuple(r.get(key) or "" for key in SETTING_KEYS), []).append(r)
    out = []
    for key, runs in groups.items():
        runs = sorted(runs, key=lambda r: int(r.get("seed") or 0))
        first = runs[0]
        out.append(
            Setting(
                settings=key,
                seeds=tuple(int(r.get("seed") or 0) for r in runs),
                errors_mm=tuple(float(r["max_tip_error_m"]) * 1e3 for r in runs),
                peak_n=float(first["peak_force_n"]),
                rms_n=float(first["rms_force_n"]),
                chatter_n=float(first["chatter_n"]),
            )
        )
    return sorted(out, key=lambda g: g.worst_mm)


def choose(groups: list[Setting], peak: float = PEAK_LIMIT_N, chatter: float = CHATTER_LIMIT_N) -> int | None:
    """Index in ``groups`` of the setting with the least worst max tip error over its seeds among those
    whose first seed has a peak leg force at most ``peak`` and chatter at most ``chatter`` (the rule
    the low-force preset was chosen by), or None when no setting qualifies."""
    fit = [i for i, g in enumerate(groups) if g.peak_n <= peak and g.chatter_n <= chatter]
    return min(fit, key=lambda i: groups[i].worst_mm) if fit else None


def setting_table(groups: list[Setting]) -> str:
    """Markdown table of :func:`by_setting`'s groups, the chosen one marked."""
    pick = choose(groups)
    head = list(SETTING_KEYS)
    head += ["seeds", "max tip error per seed (mm)", "worst (mm)", "first seed: peak (N)", "RMS (N)", "chatter (N)"]
    lines = ["| " + " | ".join(head) + " | chosen |", "|" + " --- |" * (len(head) + 1)]
    for i, g in enumerate(groups):
        cells = [*(md_cell(v) for v in g.settings), " ".join(str(s) for s in g.seeds)]
        cells.append(" ".join(f"{e:.4f}" for e in g.errors_mm))
        cells += [f"{g.worst_mm:.4f}", f"{g.peak_n:.1f}", f"{g.rms_n:.2f}", f"{g.chatter_n:.2f}"]
        cells.append("yes" if i == pick else "")
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
    with atomic_path(out) as temporary:  # never a partial picture
        fig.savefig(temporary, dpi=100)
    plt.close(fig)


def main(argv: Sequence[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) != 1:
        print("usage: python -m vgtarm.app.reports.force_front RUNS_DIR", file=sys.stderr)
        return 2
    folder = Path(args[0])
    rows = read_runs(folder)
    text = front_table(rows)
    groups = by_setting(rows)
    if any(len(g.seeds) > 1 for g in groups):
        rule = f"first seed's peak <= {PEAK_LIMIT_N:g} N and chatter <= {CHATTER_LIMIT_N:g} N, least worst error"
        text += f"\n## By setting, over the seeds ({rule})\n\n" + setting_table(groups)
    atomic_write_text(folder / "front.md", text)
    front_figure(rows, folder / "front.png")
    print(f"{len(rows)} runs: {folder / 'front.md'}, {folder / 'front.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
