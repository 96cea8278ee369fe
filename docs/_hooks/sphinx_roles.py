"""Griffe extension of the documentation site: Sphinx roles in vgtarm's docstrings become links.

vgtarm's docstrings are Google style with Sphinx cross-reference roles (``:func:`solve_point```,
``:class:`~vgtarm.errors.PathError```, ``:mod:`.spec```), which Markdown would show as they are.
Before mkdocstrings renders a docstring, each role is rewritten to an optional autorefs
cross-reference: the name is resolved as Python would from the docstring's scope (relative
module paths included), ``~`` keeps only the last component as the text, and the reference
becomes a link wherever the API reference documents its target (plain code text elsewhere, for
a private module, without a warning). ``:pep:`N``` becomes the text "PEP N".

vgtarm documents many module constants with Sphinx's ``#:`` comments on the lines just above
them (``#: Joint names, in the order of the joint vector q.``); griffe reads only string
docstrings, so an attribute without one gets those comment lines as its docstring. An entry of
an ``Attributes:`` section that names several attributes (``q, qd, qdd: joint values, rates and
accelerations``), which Google style does not allow, becomes one entry per name with the same
description.

Used only by ``mkdocs.yml`` (``plugins.mkdocstrings...extensions``); not part of the package.
"""

from __future__ import annotations

import html
import re
from typing import Any

import griffe

ROLE = re.compile(r":(?P<role>[a-z]+):`(?P<body>[^`]+)`")
"""A Sphinx role: ``:role:`text```."""
EXPLICIT = re.compile(r"^(?P<title>.*?)\s*<(?P<target>[^<>]+)>$")
"""The explicit form of a role's text: ``title <target>``."""
PYTHON_ROLES = frozenset({"func", "class", "meth", "attr", "data", "mod", "obj", "exc", "const"})


def _scope_module(obj: griffe.Object) -> griffe.Module:
    return obj if isinstance(obj, griffe.Module) else obj.module


def _resolve(obj: griffe.Object, target: str) -> str:
    """The full dotted path that ``target`` names in the scope of ``obj`` (best effort)."""
    if target.startswith("."):
        module = _scope_module(obj)
        base = module.path if module.is_package or module.is_init_module else module.parent.path  # type: ignore[union-attr]
        rest = target[1:]
        while rest.startswith("."):
            base, rest = base.rpartition(".")[0], rest[1:]
        return f"{base}.{rest}" if rest else base
    head, _, tail = target.partition(".")
    try:
        resolved = obj.resolve(head)
    except (griffe.NameResolutionError, AttributeError, KeyError):
        return target
    return f"{resolved}.{tail}" if tail else resolved


SECTION = re.compile(r"^(?P<indent> *)Attributes:\s*$")
SHARED_ENTRY = re.compile(r"^(?P<indent> +)(?P<names>\w+(?:, \w+)+)(?P<rest>(?: \([^)]*\))?:(?: .*)?)$")


def split_shared_entries(text: str) -> str:
    """``a, b: description`` in an ``Attributes:`` section as ``a: description`` and
    ``b: description``, each with the entry's continuation lines."""
    lines = text.splitlines()
    out: list[str] = []
    section_indent: int | None = None
    index = 0
    while index < len(lines):
        line = lines[index]
        header = SECTION.match(line)
        if header:
            section_indent = len(header["indent"])
        elif line.strip() and section_indent is not None and len(line) - len(line.lstrip()) <= section_indent:
            section_indent = None
        entry = SHARED_ENTRY.match(line) if section_indent is not None else None
        if entry is None or len(entry["indent"]) <= section_indent:  # type: ignore[operator]
            out.append(line)
            index += 1
            continue
        depth, end = len(entry["indent"]), index + 1
        while end < len(lines) and lines[end].strip() and len(lines[end]) - len(lines[end].lstrip()) > depth:
            end += 1
        for name in entry["names"].split(", "):
            out.extend([f"{entry['indent']}{name}{entry['rest']}", *lines[index + 1 : end]])
        index = end
    return "\n".join(out)


def _rewrite(obj: griffe.Object, text: str) -> str:
    def replace(match: re.Match[str]) -> str:
        role, body = match["role"], match["body"].strip()
        if role == "pep":
            return f"PEP {body}"
        if role not in PYTHON_ROLES:
            return f"`{body}`"
        explicit = EXPLICIT.match(body)
        if explicit:
            title, target = explicit["title"], explicit["target"]
        else:
            target = body.lstrip("~")
            title = target.rsplit(".", 1)[-1] if body.startswith("~") else target.lstrip(".")
        target = target.rstrip("()")
        path = _resolve(obj, target)
        return f'<autoref identifier="{html.escape(path)}" optional><code>{html.escape(title)}</code></autoref>'

    return ROLE.sub(replace, split_shared_entries(text))


def _comment_docstring(attr: griffe.Attribute) -> griffe.Docstring | None:
    """The ``#:`` comment lines right above an attribute's assignment, as its docstring."""
    lines, number = attr.module.lines, (attr.lineno or 0) - 2  # the line above, 0-based
    found: list[str] = []
    while 0 <= number < len(lines) and lines[number].lstrip().startswith("#:"):
        found.insert(0, lines[number].lstrip()[2:].strip())
        number -= 1
    return griffe.Docstring("\n".join(found), lineno=number + 2, parent=attr) if found else None


class SphinxRoles(griffe.Extension):
    """Rewrite the Sphinx roles of every docstring of a loaded package; give attributes their
    ``#:`` comments as docstrings."""

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        stack: list[griffe.Object] = [pkg]
        while stack:
            obj = stack.pop()
            if obj.docstring is None and isinstance(obj, griffe.Attribute):
                obj.docstring = _comment_docstring(obj)
            if obj.docstring is not None:
                obj.docstring.value = _rewrite(obj, obj.docstring.value)
            stack.extend(member for member in obj.members.values() if not member.is_alias)  # type: ignore[misc]
