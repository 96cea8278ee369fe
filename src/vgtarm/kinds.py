"""What a file is: the kinds of CSV and TOML files vgtarm reads and writes, recognised by their
header or their top-level tables.

A reader that finds a file of another kind than it expects (the joint reference ``vgtarm ik``
writes given as a path, a study file given as a robot, a robot file given as a study) refuses it
in one line naming the file, what it expected and what it found, with what the file looks like
when it is one of these kinds. The line never quotes the file: it gives the number of columns and
their names only when they look like column names, and the tables that identify a kind.
"""

from __future__ import annotations

import json
import re
import tomllib
from collections.abc import Mapping, Sequence
from typing import Any

from .errors import cut

#: The top-level tables of the paper's 7-joint robot file (and its optional keys).
ROBOT_TABLES = ("geometry", "limits", "home", "bodies")
ROBOT_OPTIONAL = ("name", "friction", "environment")
#: Keys only a stack's robot file has.
STACK_KEYS = ("modules", "end_effector")
#: The tables of a study file.
STUDY_TABLES = ("study", "grid", "random")
#: What a robot file is expected to be, for messages.
ROBOT_EXPECTED = "a robot file (the tables [geometry], [limits], [home] and [bodies], or a stack's [[modules]])"
#: What a study file is expected to be, for messages.
STUDY_EXPECTED = "a study file (the table [study], with [grid] and [random] if any)"
#: What a robot file of the paper's 7-joint format is expected to be, for messages.
SEVEN_JOINT_EXPECTED = "a robot file of the 7-joint format (the tables [geometry], [limits], [home] and [bodies])"
#: What a stack's robot file is expected to be, for messages.
STACK_EXPECTED = "a stack robot file ([[modules]] and [end_effector]; `vgtarm convert-robot` converts a robot file)"

#: The top-level keys that identify each kind of TOML file (robot files first: their check wins).
_TOML_KINDS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("a stack robot file", STACK_KEYS),
    ("a robot file", ROBOT_TABLES),
    ("a study file", STUDY_TABLES),
    ("a Python project file (pyproject.toml)", ("project", "build-system")),
)
#: A cell that looks like a column name (shown in a message); anything else is only counted.
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_.()\-]{0,30}")
#: Column names shown before "..." in a message.
_SHOWN_COLUMNS = 5
#: Largest text parsed to say what a file that is not CSV looks like (bytes).
_SNIFF_LIMIT = 1 << 20


def toml_kind(data: object) -> tuple[str, list[str]] | None:
    """The kind of a parsed TOML file, and the top-level tables that identify it, or None."""
    if not isinstance(data, Mapping):
        return None
    for kind, keys in _TOML_KINDS:
        found = [key for key in keys if key in data]
        if found:
            return kind, found
    return None


def _tables(found: Sequence[str]) -> str:
    """``["study", "grid"]`` as ``[study], [grid]`` (``[[modules]]`` for the stack's list)."""
    return ", ".join(f"[[{key}]]" if key == "modules" else f"[{key}]" for key in found)


def other_toml(data: object, expected: str) -> str | None:
    """What a parsed TOML file is when it is recognised as another kind than ``expected`` (a kind
    of :data:`_TOML_KINDS`, or ``"robot"``: either robot file), as the end of a refusal: ``"a study
    file (it has the tables [study], [grid]); expected a robot file (...)"``; None when it is of
    the expected kind or of no kind known here (the reader's own checks then say what is wrong)."""
    found = toml_kind(data)
    if found is None:
        return None
    kind, keys = found
    if kind == expected or (expected == "robot" and kind in ("a robot file", "a stack robot file")):
        return None
    wanted = {
        "robot": ROBOT_EXPECTED,
        "a robot file": SEVEN_JOINT_EXPECTED,
        "a study file": STUDY_EXPECTED,
        "a stack robot file": STACK_EXPECTED,
    }.get(expected, expected)
    return f"{kind} (it has the table{'s' if len(keys) > 1 else ''} {_tables(keys)}); expected {wanted}"


def csv_kind(cells: Sequence[str]) -> str | None:
    """What a CSV file with the header ``cells`` is, when it is one vgtarm reads or writes."""
    names = [cell.strip() for cell in cells]
    lower = [name.lower() for name in names]
    if lower == ["t", "x", "y", "z"]:
        return "a path file"
    if lower[:4] == ["t", "x", "y", "z"] and len(names) > 4 and (len(names) - 4) % 3 == 0:
        return "the joint reference `vgtarm ik` writes"
    if names[:4] == ["t", "x_d", "y_d", "z_d"]:
        return "a run's time series (timeseries.csv of `vgtarm simulate --out`)"
    if names[:2] == ["sample", "time_s"]:
        return "a run's GA activations (ga_activations.csv)"
    if names[:1] == ["id"] and "error" in names:
        return "a study's results table (results.csv of `vgtarm study run`)"
    if names[:2] == ["t", "q_d_1"]:
        return "a reference for the exported controller's replay"
    if names[:2] == ["t", "q_1"]:
        return "measurements for the exported controller's replay"
    if names[:2] == ["t", "F_1"]:
        return "the efforts the exported controller's replay writes"
    return None


def _text_kind(text: str) -> str | None:
    """What a text that is not the expected CSV looks like when it is TOML or JSON."""
    if len(text) > _SNIFF_LIMIT:
        return None
    stripped = text.lstrip()
    if stripped.startswith(("{", "[")):
        try:
            json.loads(stripped)
        except (ValueError, RecursionError):
            pass
        else:
            return "a JSON file"
    try:
        data: Any = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError, ValueError):
        return None
    if not data:
        return None
    found = toml_kind(data)
    return "a TOML file" if found is None else f"{found[0]} (TOML)"


def found_columns(cells: Sequence[str], *, text: str = "", quote: bool = True, expected: str = "") -> str:
    """What a header row ``cells`` holds, for a refusal: ``"found 25 columns starting t, x, y, z,
    s1, ...: this looks like the joint reference `vgtarm ik` writes"``.

    Column names are shown (escaped and cut) only with ``quote`` and when every cell shown looks
    like a column name; else only their number. ``text``, the whole file, is looked at (not shown)
    to say it is TOML or JSON when it is not CSV at all. A kind that starts with ``expected`` (the
    kind the reader wanted, with other columns) is not named."""
    names = [cell.strip() for cell in cells]
    kind = csv_kind(names)
    if kind is not None and expected and kind.startswith(expected):
        kind = None
    other = None if kind is not None or not text else _text_kind(text)
    if other is not None:  # not CSV at all: nothing of it is shown
        return f"found no CSV header: this looks like {other}"
    count = f"{len(names)} column{'s' if len(names) != 1 else ''}"
    head = names[:_SHOWN_COLUMNS]
    if quote and head and all(_NAME.fullmatch(name) for name in head):
        more = ", ..." if len(names) > len(head) else ""
        listed = f"{count} {'starting ' if more else ''}{cut(', '.join(head), 80)}{more}"
    elif quote and head:
        listed = f"{count}, not column names"
    else:
        listed = count
    return f"found {listed}" + (f": this looks like {kind}" if kind else "")
