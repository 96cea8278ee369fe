"""``vgtarm reproduce --seeds N``: every reported run over N seeds, beside the paper's single numbers.

The runs are a study (:mod:`vgtarm.study`) per case and rates, run on a local Dask cluster into
``DIR/seeds`` (resumable like any study); seed 0 of each is the single run of the main table.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ... import checks
from ...experiment.cases import PAPER_RESULTS
from ..study_points import check_point, execute_point
from .runs import RunSpec

#: Most seeds of ``reproduce --seeds``: 120,000 runs of about a second, a day and more of work.
MAX_SEEDS = 10_000


def seed_rows(
    folder: str | Path,
    seeds: int,
    specs: Sequence[RunSpec],
    *,
    integrator: str = "euler",
    substeps: int = 1,
    config: str | Path | None = None,
) -> list[dict[str, Any]]:
    """Run every spec with seeds ``0..seeds-1`` (a study per case and rates); returns the rows."""
    from ...study.runner import run_study
    from ...study.spec import parse_study

    checks.whole("seeds", seeds, 1, MAX_SEEDS)
    rows: list[dict[str, Any]] = []
    for case, rates in sorted({(s.case, s.rates) for s in specs}):
        chosen = [s for s in specs if (s.case, s.rates) == (case, rates)]
        study = parse_study(
            {
                "study": {
                    "name": f"case {case}, {rates} rates, {seeds} seeds",
                    "case": case,
                    "rates": rates,
                    "seeds": seeds,
                    **({"robot": str(Path(config).resolve())} if config is not None else {}),
                },
                "grid": {
                    "controller": sorted({s.controller for s in chosen}),
                    "external_force": sorted({s.external_force for s in chosen}),
                    "integrator": integrator,
                    "substeps": substeps,
                },
            },
            source="reproduce --seeds",
        )
        wanted = {(s.controller, s.external_force) for s in chosen}
        made = run_study(study, folder, execute_point, check=check_point, progress=False)
        rows += [r for r in made.rows if (r["controller"], r["external_force"]) in wanted]
    return rows


def seed_section(
    folder: str | Path,
    seeds: int,
    specs: Sequence[RunSpec],
    *,
    integrator: str = "euler",
    substeps: int = 1,
    config: str | Path | None = None,
) -> list[str]:
    """The report's section: per run, seed 0, the mean and spread over the seeds, the paper's figure."""
    rows = seed_rows(folder, seeds, specs, integrator=integrator, substeps=substeps, config=config)
    lines = [
        f"## Over {seeds} seeds",
        "",
        f"Every run again with seeds 0 to {seeds - 1} of the disturbance and the GA (a study in `seeds/`, run on"
        " Dask; `vgtarm study report seeds` tabulates it). Maximum tip error in mm: seed 0 (the table above),"
        " mean and sample standard deviation, smallest and largest over the seeds.",
        "",
        "| case | controller | tool force | rates | paper | seed 0 | mean ± std | min – max | failed |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for spec in specs:
        mine = [
            r
            for r in rows
            if (r["case"], r["controller"], r["external_force"], r["rates"])
            == (spec.case, spec.controller, spec.external_force, spec.rates)
        ]
        ok = [r for r in mine if r["success"]]
        values = np.array([1e3 * float(r["max_tip_error_m"]) for r in ok])
        first = next((1e3 * float(r["max_tip_error_m"]) for r in ok if r["seed"] == 0), math.nan)
        paper = PAPER_RESULTS.get((spec.case, spec.controller, spec.external_force))
        spread = f"{values.mean():.4f} ± {values.std(ddof=1):.4f}" if len(values) > 1 else "—"
        extent = f"{values.min():.4f} – {values.max():.4f}" if len(values) else "—"
        lines.append(
            f"| {spec.case} | {spec.controller.upper()} | {'yes' if spec.external_force else 'no'} |"
            f" {'exact' if spec.rates == 'exact' else 'finite diff.'} | {paper.text if paper else '—'} |"
            f" {first:.4f} | {spread} | {extent} | {len(mine) - len(ok)} of {len(mine)} |"
        )
    return lines
