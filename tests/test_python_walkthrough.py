"""docs/python.md is a walkthrough whose Python cells run, in order, in one namespace, as a
notebook would run them; so do the README's Python examples: a page that stops working fails here."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import matplotlib
import pytest

REPO = Path(__file__).resolve().parents[1]
PAGE = REPO / "docs" / "python.md"
CELL = re.compile(r"^```python\n(.*?)^```", re.MULTILINE | re.DOTALL)


def _cells(text: str | None = None) -> list[str]:
    return CELL.findall(PAGE.read_text() if text is None else text)


def _readme_python_section() -> str:
    text = (REPO / "README.md").read_text()
    start = text.index("\n## Python\n")
    return text[start : text.index("\n## ", start + 1)]


def test_the_page_has_cells():
    assert len(_cells()) >= 5


def _run(cells: list[str], where: str) -> dict[str, object]:
    namespace: dict[str, object] = {"__name__": "walkthrough"}
    for number, cell in enumerate(cells, start=1):
        try:
            exec(compile(cell, f"{where}, cell {number}", "exec"), namespace)  # noqa: S102
        except Exception as exc:  # noqa: BLE001 - name the cell that failed
            pytest.fail(f"{where} cell {number} failed: {type(exc).__name__}: {exc}\n{cell}")
    return namespace


def test_every_cell_runs_in_order(tmp_path, monkeypatch):
    matplotlib.use("Agg")
    monkeypatch.chdir(tmp_path)
    namespace = _run(_cells(), PAGE.name)
    assert namespace["ik"].success  # type: ignore[attr-defined]


def test_the_readmes_python_examples_run(tmp_path, monkeypatch):
    matplotlib.use("Agg")
    monkeypatch.chdir(tmp_path)
    shutil.copytree(REPO / "examples", tmp_path / "examples")  # the README's paths are from the repository's root
    cells = _cells(_readme_python_section())
    assert len(cells) >= 2
    namespace = _run(cells, "README.md, section Python")
    assert namespace["run_scm"].success and (tmp_path / "out" / "compare.png").is_file()  # type: ignore[attr-defined]
