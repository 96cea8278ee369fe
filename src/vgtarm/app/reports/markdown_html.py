"""The Markdown that vgtarm's reports write, as HTML: one source for ``report.md`` and ``report.html``.

``report.html`` shows ``report.md``'s text converted here, so the two hold the same sections under
the same headings and cannot drift apart. The converter reads the part of Markdown (CommonMark
and GitHub's tables) that the reports write, and no more:

- blocks: ATX headings (``#`` to ``######``), paragraphs (lines joined), tight bullet lists
  (``- `` items, an indented line continuing the item), pipe tables (a header row, a ``---``
  row, body rows), and an image alone on its line (``![alt](file)``);
- inline: backslash escapes of ASCII punctuation, character references (``&lt;``), code spans,
  ``**strong**`` and ``*emphasis*``, and links ``[text](destination)`` to relative paths.

User text reaches the Markdown through :mod:`vgtarm.markup` (``md_text``, ``md_cell``,
``md_code``), which escapes every character that could start markup there; every character
the converter outputs as text goes through :func:`vgtarm.markup.html_text`. A link whose
destination has a scheme (``javascript:``, ``http:``) or an image that is not a plain file name
is written as its text, so the page links only into its own folder. A Markdown library
(markdown-it-py) would do the same job but is not a dependency of vgtarm; this subset is
about a hundred lines and is tested against the reports it converts.
"""

from __future__ import annotations

import html
import re
from collections.abc import Callable
from dataclasses import dataclass, field

from ...markup import html_text

__all__ = ["Heading", "headings", "slug", "to_html"]

_HEADING = re.compile(r"^(#{1,6})[ \t]+(.*?)(?:[ \t]+#+)?[ \t]*$")
_IMAGE = re.compile(r"^!\[((?:[^\]\\]|\\.)*)\]\(([^()\s]+)\)$")
_ITEM = re.compile(r"^[-*+][ \t]+(.*)$")
_RULE_ROW = re.compile(r"^\|?(\s*:?-+:?\s*\|)+\s*:?-*:?\s*$")
_ESCAPABLE = set("!\"#$%&'()*+,-./:;<=>?@[\\]^_`{|}~")
_ENTITY = re.compile(r"&(#[0-9]{1,7}|#[xX][0-9a-fA-F]{1,6}|[A-Za-z][A-Za-z0-9]{1,31});")
#: A link destination the page may hold: a relative path (percent-encoded), no scheme, not from ``/``.
_RELATIVE = re.compile(r"^(?![A-Za-z][A-Za-z0-9+.-]*:)(?!/)[A-Za-z0-9%._~!$&'()*+,;=:@/-]+$")


@dataclass(frozen=True)
class Heading:
    """A heading of the document: level (1 to 6), its text as shown, and its element id."""

    level: int
    text: str
    id: str


@dataclass
class _Converted:
    parts: list[str] = field(default_factory=list)
    headings: list[Heading] = field(default_factory=list)
    ids: set[str] = field(default_factory=set)
    tables: int = 0

    def html(self) -> str:
        return "\n".join(self.parts) + "\n"


def slug(text: str) -> str:
    """An element id from a heading's text: lower-case letters and digits joined by ``-``."""
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "section"


def to_html(
    markdown: str,
    *,
    image: Callable[[str, str], str] | None = None,
    after_heading: dict[str, str] | None = None,
    first_table_id: str | None = None,
) -> str:
    """``markdown`` (the subset above) as HTML.

    Args:
        markdown: the document.
        image: the HTML of an image line from its alt text and file name (both as written, the
            alt text unescaped); default an ``<img>`` whose ``src`` is the file name.
        after_heading: HTML (trusted: vgtarm's own) to place right after the heading of that
            text, e.g. the interactive figures after "Figures".
        first_table_id: the ``id`` of the first table.
    """
    return _convert(markdown, image, after_heading or {}, first_table_id).html()


def headings(markdown: str) -> list[Heading]:
    """The headings of ``markdown`` as :func:`to_html` writes them (text as shown, ids)."""
    return _convert(markdown, None, {}, None).headings


def _convert(
    markdown: str,
    image: Callable[[str, str], str] | None,
    after: dict[str, str],
    first_table_id: str | None,
) -> _Converted:
    out = _Converted()
    lines = markdown.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    i = 0
    while i < len(lines):
        line = lines[i]
        if not line.strip():
            i += 1
            continue
        heading = _HEADING.match(line)
        if heading:
            level, text = len(heading.group(1)), _inline(heading.group(2))
            shown = html.unescape(re.sub(r"<[^>]*>", "", text))
            ident = _unique(slug(shown), out.ids)
            out.headings.append(Heading(level, shown, ident))
            out.parts.append(f'<h{level} id="{ident}">{text}</h{level}>')
            if shown in after:
                out.parts.append(after[shown])
            i += 1
            continue
        picture = _IMAGE.match(line.strip())
        if picture:
            alt, src = _unescape(picture.group(1)), picture.group(2)
            if image is not None:
                out.parts.append(image(alt, src))
            elif _RELATIVE.match(src):
                out.parts.append(f'<p><img src="{html_text(src)}" alt="{html_text(alt)}"></p>')
            else:
                out.parts.append(f"<p>{html_text(line.strip())}</p>")
            i += 1
            continue
        if line.lstrip().startswith("|") and i + 1 < len(lines) and _RULE_ROW.match(lines[i + 1].strip()):
            end = i + 2
            while end < len(lines) and lines[end].lstrip().startswith("|"):
                end += 1
            table_id = first_table_id if out.tables == 0 and first_table_id else None
            out.parts.append(_table(lines[i], lines[i + 2 : end], table_id))
            out.tables += 1
            i = end
            continue
        if _ITEM.match(line):
            items: list[list[str]] = []
            while i < len(lines) and lines[i].strip():
                item = _ITEM.match(lines[i])
                if item:
                    items.append([item.group(1)])
                else:  # an indented (or lazy) continuation line of the item's paragraph
                    items[-1].append(lines[i].strip())
                i += 1
            body = "".join(f"<li>{_inline(chr(10).join(item))}</li>" for item in items)
            out.parts.append(f"<ul>{body}</ul>")
            continue
        paragraph = []
        while i < len(lines) and lines[i].strip() and not _starts_block(lines, i):
            paragraph.append(lines[i].strip())
            i += 1
        out.parts.append(f"<p>{_inline(chr(10).join(paragraph))}</p>")
    return out


def _starts_block(lines: list[str], i: int) -> bool:
    line = lines[i]
    if _HEADING.match(line) or _ITEM.match(line) or _IMAGE.match(line.strip()):
        return True
    return line.lstrip().startswith("|") and i + 1 < len(lines) and bool(_RULE_ROW.match(lines[i + 1].strip()))


def _unique(ident: str, seen: set[str]) -> str:
    candidate, n = ident, 1
    while candidate in seen:
        n += 1
        candidate = f"{ident}-{n}"
    seen.add(candidate)
    return candidate


def _cells(row: str) -> list[str]:
    """The cells of a table row: split at ``|`` that no backslash escapes (GitHub's rule, code
    spans included), the outer pipes dropped."""
    text = row.strip()
    if text.startswith("|"):
        text = text[1:]
    if text.endswith("|") and not text.endswith("\\|"):
        text = text[:-1]
    cells, current, k = [], [], 0
    while k < len(text):
        if text[k] == "\\" and k + 1 < len(text) and text[k + 1] == "|":
            current.append("\\|")
            k += 2
            continue
        if text[k] == "|":
            cells.append("".join(current).strip())
            current = []
        else:
            current.append(text[k])
        k += 1
    cells.append("".join(current).strip())
    return cells


def _table(header: str, rows: list[str], table_id: str | None) -> str:
    head = _cells(header)
    width = len(head)
    attribute = f' id="{html_text(table_id)}"' if table_id else ""
    parts = [f"<table{attribute}><thead><tr>", *(f"<th>{_inline(c)}</th>" for c in head), "</tr></thead><tbody>"]
    for row in rows:
        cells = (_cells(row) + [""] * width)[:width]  # GitHub's rule: pad or cut to the header's width
        parts += ["<tr>", *(f"<td>{_inline(c)}</td>" for c in cells), "</tr>"]
    parts.append("</tbody></table>")
    return "".join(parts)


def _unescape(text: str) -> str:
    """Markdown text without markup as the characters it shows: escapes and references resolved."""
    return _ENTITY.sub(lambda m: html.unescape(m.group(0)), re.sub(r"\\([!-/:-@\[-`{-~])", r"\1", text))


def _inline(text: str) -> str:
    """Inline Markdown as HTML (see the module's docstring)."""
    out: list[str] = []
    k, n = 0, len(text)
    while k < n:
        c = text[k]
        if c == "\\" and k + 1 < n and text[k + 1] in _ESCAPABLE:
            out.append(html_text(text[k + 1]))
            k += 2
        elif c == "\\" and k + 1 < n and text[k + 1] == "\n":  # a hard line break
            out.append("<br>")
            k += 2
        elif c == "&" and (entity := _ENTITY.match(text, k)):
            out.append(html_text(html.unescape(entity.group(0))))
            k = entity.end()
        elif c == "`":
            run = len(text[k:]) - len(text[k:].lstrip("`"))
            close = _closing_backticks(text, k + run, run)
            if close < 0:
                out.append(html_text("`" * run))
                k += run
                continue
            code = text[k + run : close].replace("\n", " ")
            if len(code) > 2 and code[0] == code[-1] == " " and code.strip():
                code = code[1:-1]
            out.append(f"<code>{html_text(code)}</code>")
            k = close + run
        elif text.startswith("**", k) and (end := _closing(text, k + 2, "**")) > k + 2:
            out.append(f"<strong>{_inline(text[k + 2 : end])}</strong>")
            k = end + 2
        elif c == "*" and (end := _closing(text, k + 1, "*")) > k + 1 and text[k + 1] != " ":
            out.append(f"<em>{_inline(text[k + 1 : end])}</em>")
            k = end + 1
        elif c == "[" and (link := _link(text, k)) is not None:
            label, destination, end = link
            if _RELATIVE.match(destination):
                out.append(f'<a href="{html_text(destination)}">{_inline(label)}</a>')
            else:  # not a path of the page's folder: shown as written
                out.append(html_text(text[k:end]))
            k = end
        elif c == "\n":
            out.append("\n")
            k += 1
        else:
            out.append(html_text(c))
            k += 1
    return "".join(out)


def _closing_backticks(text: str, start: int, run: int) -> int:
    """Where the backtick run of length ``run`` closing a code span opened before ``start`` begins; -1 if none."""
    k = start
    while k < len(text):
        if text[k] == "`":
            length = len(text[k:]) - len(text[k:].lstrip("`"))
            if length == run:
                return k
            k += length
        else:
            k += 1
    return -1


def _closing(text: str, start: int, marker: str) -> int:
    """Where ``marker`` next occurs unescaped and outside code spans from ``start``; -1 if none.
    A closing marker does not follow a space (CommonMark's flanking rule, simplified)."""
    k = start
    while k < len(text):
        if text[k] == "\\":
            k += 2
            continue
        if text[k] == "`":
            run = len(text[k:]) - len(text[k:].lstrip("`"))
            close = _closing_backticks(text, k + run, run)
            k = close + run if close >= 0 else k + run
            continue
        if text.startswith(marker, k) and text[k - 1] != " " and not (marker == "*" and text.startswith("**", k)):
            return k
        if marker == "*" and text.startswith("**", k):
            k += 2
            continue
        k += 1
    return -1


def _link(text: str, start: int) -> tuple[str, str, int] | None:
    """``[label](destination)`` at ``start``: the label, the destination and the end; None if not a link."""
    k, depth = start + 1, 1
    while k < len(text):
        if text[k] == "\\":
            k += 2
            continue
        if text[k] == "`":
            run = len(text[k:]) - len(text[k:].lstrip("`"))
            close = _closing_backticks(text, k + run, run)
            k = close + run if close >= 0 else k + run
            continue
        if text[k] == "[":
            depth += 1
        elif text[k] == "]":
            depth -= 1
            if depth == 0:
                break
        k += 1
    else:
        return None
    if not text.startswith("(", k + 1):
        return None
    close = text.find(")", k + 2)
    if close < 0:
        return None
    destination = text[k + 2 : close].strip()
    if destination.startswith("<") and destination.endswith(">"):
        destination = destination[1:-1]
    if not destination or any(ch.isspace() for ch in destination):
        return None
    return text[start + 1 : k], destination, close + 1
