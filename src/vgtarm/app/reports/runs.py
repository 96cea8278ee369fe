"""The runs of the reproduction and the one table both reports show of them.

:class:`RunSpec` names one run the paper reports (case, controller, tool force, rates) and its
folder; :data:`TABLE_COLUMNS` and :func:`table_row` are the comparison table, defined once and
used by ``report.md`` (:mod:`.reproduce`) and ``report.html`` (:mod:`.html`) alike.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from ...experiment.cases import PAPER_RESULTS
from ...markup import md_link, md_text


@dataclass(frozen=True)
class RunSpec:
    """One run of the reproduction."""

    case: int
    controller: str
    external_force: bool
    rates: str
    #: The desired path's name of a run that is not a case study (case 0), as its summary records it.
    name: str = ""

    @property
    def case_text(self) -> str:
        """The table's case cell: the case's number, else the path's name (a dash if unknown)."""
        return str(self.case) if self.case else (self.name or "—")

    @property
    def folder(self) -> str:
        force = "_force" if self.external_force else ""
        rates = "" if self.rates == "exact" else "_fd"
        return f"case{self.case}_{self.controller}{force}{rates}"

    @property
    def label(self) -> str:
        text = self.controller.upper() + (" + tool force" if self.external_force else "")
        return text + (" (FD rates)" if self.rates == "finite_difference" else "")


def paper_runs(rates: Iterable[str] = ("exact", "finite_difference")) -> list[RunSpec]:
    """Every combination the paper reports, for each way of computing the reference rates."""
    combos = [
        (1, "cfc", False),
        (1, "scm", False),
        (2, "cfc", False),
        (2, "scm", False),
        (2, "cfc", True),
        (2, "scm", True),
    ]
    return [RunSpec(c, ctrl, force, r) for r in rates for c, ctrl, force in combos]


def mm(value: float | None) -> str:
    """A length in m as the reports write it: mm with four decimals, a dash for none."""
    return "—" if value is None else f"{value * 1e3:.4f}"


#: Columns of the report's table (``report.md`` and ``report.html`` show the same table).
TABLE_COLUMNS = (
    "case",
    "controller",
    "tool force",
    "rates",
    "paper",
    "ours: max (mm)",
    "ours: max after 0.2 s (mm)",
    "ours: RMS (mm)",
    "peak force (N)",
    "GA activations",
    "GA time (s)",
    "wall (s)",
    "folder",
)


def table_row(spec: RunSpec, summary: dict[str, Any], folder: str | None = None) -> list[str]:
    """The cells of one run in the report's table (:data:`TABLE_COLUMNS`), as plain text (each
    format escapes them: :mod:`vgtarm.markup`); ``folder`` defaults to the spec's folder name."""
    s = summary
    paper = PAPER_RESULTS.get((spec.case, spec.controller, spec.external_force))
    return [
        spec.case_text,
        spec.controller.upper(),
        "yes" if spec.external_force else "no",
        "exact" if spec.rates == "exact" else "finite diff.",
        paper.text if paper else "—",
        mm(s["max_tip_error_m"]),
        mm(s["max_tip_error_after_transient_m"]),
        mm(s["rms_tip_error_m"]),
        "—" if s["peak_force_n"] is None else f"{s['peak_force_n']:.1f}",
        str(s["ga_activations"]),
        f"{s['ga_time_s']:.2f}",
        f"{s['wall_time_s']:.2f}",
        folder if folder is not None else spec.folder,
    ]


def task_note(summaries: Iterable[Mapping[str, Any]]) -> str:
    """A sentence naming the inverse-kinematics task of runs on a robot whose tip moves in a plane or a
    line (their summaries' ``ik_task``), or "" when every run tracked the tip's three coordinates."""
    tasks = sorted({str(s["ik_task"]) for s in summaries if s.get("ik_task")})
    if not tasks:
        return ""
    return (
        f"Task: {'; '.join(tasks)} (the robot's tip cannot leave it; the inverse kinematics tracks the path's"
        " coordinates there and spends the remaining freedom on eq. 12)."
    )


def folder_cell(path: str, shown: str | None = None) -> str:
    """The Markdown of a table's folder cell: the run's folder ``path`` (relative to the report,
    ``/`` between parts) shown as ``shown`` (default ``path``) and linked, then a link to its
    ``summary.json``; both escaped (:mod:`vgtarm.markup`)."""
    folder = path.rstrip("/")
    name = (shown if shown is not None else folder).rstrip("/") + "/"
    return f"{md_link(md_text(name), folder + '/')} {md_link('summary', folder + '/summary.json')}"
