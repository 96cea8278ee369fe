"""docs/python.md is a walkthrough whose Python cells run, in order, in one namespace, as a
notebook would run them: a page that stops working fails here."""

from __future__ import annotations

import re
from pathlib import Path

import matplotlib
import pytest

PAGE = Path(__file__).resolve().parents[1] / "docs" / "python.md"
CELL = re.compile(r"^```python\n(.*?)^```", re.MULTILINE | re.DOTALL)


def _cells() -> list[str]:
    return CELL.findall(PAGE.read_text())


def test_the_page_has_cells():
    assert len(_cells()) >= 5


def test_every_cell_runs_in_order(tmp_path, monkeypatch):
    matplotlib.use("Agg")
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, object] = {"__name__": "walkthrough"}
    for number, cell in enumerate(_cells(), start=1):
        try:
            exec(compile(cell, f"{PAGE.name}, cell {number}", "exec"), namespace)  # noqa: S102
        except Exception as exc:  # noqa: BLE001 - name the cell that failed
            pytest.fail(f"{PAGE.name} cell {number} failed: {type(exc).__name__}: {exc}\n{cell}")
    assert namespace["ik"].success  # type: ignore[attr-defined]
