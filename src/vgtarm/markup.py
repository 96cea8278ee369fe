"""Users' text made inert where vgtarm writes markup: HTML, Plotly's labels, Markdown, Matplotlib.

Folder and file names, robot and joint names, a saved run's metadata and a study's fields come
from users. Wherever one of them enters a page, a Markdown document or a figure it goes through
one of these functions, which make it show as the characters it is and never become an element,
an attribute, a link, an image, a heading, a table column, a template field or math. vgtarm's own
text (headings, units, numbers) is written as it is.

Every function first shows control and other unprintable characters escaped (``\\n``, ``\\x1b``:
:func:`vgtarm.errors.escape`), so a name cannot break a line of the output either. Text without
any character that these formats treat specially comes back unchanged (``case1_cfc`` stays
``case1_cfc``), except for Markdown's backslash escapes below, which a renderer shows as the
plain character.

- :func:`html_text`: text and quoted attribute values of HTML (``&``, ``<``, ``>``, ``"``, ``'``
  as character references).
- :func:`plotly_text`: strings that Plotly renders (titles, trace names, axis titles, hover
  templates). Plotly reads a small subset of HTML in them (``<b>``, ``<a href>``, ``<br>``) and
  ``%{...}`` as template fields; ``&``, ``<``, ``>``, ``{`` and ``}`` are written as character
  references, which Plotly shows as the characters. (The figure's JSON itself is made safe inside
  the page's ``<script>`` by Plotly, which writes ``<``, ``>`` and ``/`` as ``\\u003c`` ...)
- :func:`md_text`, :func:`md_cell`, :func:`md_code`: Markdown (CommonMark and GitHub's dialect)
  inside a line of text, in a table cell, in a code span.
- :func:`mpl_text`: Matplotlib text (titles, labels), where a pair of ``$`` starts math.
- :func:`url_path`: a relative path as a link's destination (percent-encoded: no scheme, no
  space, nothing a format reads), and :func:`md_link` a Markdown link to it.
"""

from __future__ import annotations

import math
import re
from urllib.parse import quote

from .errors import escape

__all__ = ["html_text", "md_cell", "md_code", "md_link", "md_text", "mpl_text", "plotly_text", "url_path"]

_HTML = {"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#x27;"}
_PLOTLY = {"&": "&amp;", "<": "&lt;", ">": "&gt;", "{": "&#123;", "}": "&#125;"}
#: Markdown's inline syntax: raw HTML, entities and autolinks in angle brackets become character
#: references; the characters of escapes, code, emphasis, strikethrough, links and images, table
#: cells, math and headings get a backslash (a renderer shows the plain character), and so do the
#: ``:`` of ``scheme://`` and the ``.`` of ``www.``, which GitHub turns into links.
_MD_ENTITIES = {"&": "&amp;", "<": "&lt;", ">": "&gt;"}
_MD_SPECIAL = re.compile(r"[&<>\\`*_~\[\]|$#]|:(?=//)|(?<=[Ww]{3})\.")
#: The start of a block: a list item (``- ``, ``+ ``, ``1. ``, ``1) ``), a heading's underline or a
#: rule (``===``, ``---``); its marker gets a backslash. (A number such as ``0.53`` stays as it is.)
_BLOCK_START = re.compile(r"^(\s*\d{0,9})([-+=.)])(?=\s|$|[-=\s]*$)")
#: What a code span cannot hold as it is (backticks end it; a table splits at ``|``; some
#: renderers read HTML inside it).
_NOT_IN_CODE = frozenset("`|<>&")


def _text(value: object) -> str:
    return escape(value if isinstance(value, str) else str(value))


def html_text(value: object) -> str:
    """``value`` as HTML text or a quoted attribute value: ``<b>`` shows as ``<b>``."""
    return "".join(_HTML.get(c, c) for c in _text(value))


def plotly_text(value: object) -> str:
    """``value`` as a string Plotly renders (title, trace or axis name, hover template): no tag
    (``<b>``, ``<a href>``) and no template field (``%{y}``) of it acts; it shows as written."""
    return "".join(_PLOTLY.get(c, c) for c in _text(value))


def md_text(value: object) -> str:
    """``value`` as Markdown text inside a line: no HTML, link, image, code, emphasis, math,
    heading, list, quote or table cell comes of it; a renderer shows its characters. (GitHub
    still links an e-mail address, ``mailto:`` the address as written: it reads them after
    every escape.)"""
    text = _MD_SPECIAL.sub(lambda m: _MD_ENTITIES.get(m.group(0)) or "\\" + m.group(0), _text(value))
    return _BLOCK_START.sub(r"\1\\\2", text, count=1)


def md_cell(value: object) -> str:
    """``value`` as the text of a Markdown table cell: :func:`md_text`, whose ``|`` and line breaks
    already cannot add a column or a row."""
    return md_text(value)


def md_code(value: object) -> str:
    """``value`` as a Markdown code span in a line or a table cell (``case1_cfc/`` between
    backticks); when it holds a backtick, ``|``, ``<``, ``>``, ``&`` or spaces at an end, which a
    code span cannot show as they are in every renderer, as :func:`md_text` instead (plain text
    that shows them)."""
    text = _text(value)
    if not text or _NOT_IN_CODE.intersection(text) or text != text.strip():
        return md_text(text)
    return f"`{text}`"


def mpl_text(value: object) -> str:
    """``value`` as Matplotlib text: a ``$`` shows as ``$`` and starts no math."""
    return _text(value).replace("$", "\\$")


def url_path(path: str) -> str:
    """``path`` (a relative path with ``/`` between its parts) as a link's destination: every
    character but letters, digits, ``-._~`` and ``/`` percent-encoded (UTF-8), so it is read as a
    path in HTML and Markdown alike, never as a scheme (``javascript:`` becomes
    ``javascript%3A``), a query or a fragment."""
    return quote(str(path), safe="/")


def md_link(text: str, path: str) -> str:
    """A Markdown link showing ``text`` (Markdown, already escaped by the caller) to the relative
    ``path`` (:func:`url_path`)."""
    return f"[{text}]({url_path(path)})"


def html_table(header: list[str] | tuple[str, ...], rows: list[list[object]], *, caption: str = "") -> str:
    """An HTML table (for a notebook's ``_repr_html_``): every cell and the caption escaped as text."""
    head = "".join(f"<th>{html_text(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{html_text(c)}</td>" for c in row) + "</tr>" for row in rows)
    title = f"<caption>{html_text(caption)}</caption>" if caption else ""
    return f"<table>{title}<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


#: First characters that make a spreadsheet read a CSV cell as a formula.
FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")


def spreadsheet_text(text: str) -> str:
    """``text`` as a CSV cell a spreadsheet shows as text: with a leading ``'`` when its first
    character is one of :data:`FORMULA_STARTS` (the usual defence against formula injection; the
    spreadsheet hides the quote), else unchanged."""
    return f"'{text}" if text.startswith(FORMULA_STARTS) else text


def csv_cell(value: object) -> object:
    """A table value as a CSV cell: floats in full (``repr``), None and non-finite numbers empty,
    text made safe for spreadsheets (:func:`spreadsheet_text`), anything else as it is; the CSV
    writer quotes commas, quotes and line breaks."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return ""
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):
        return spreadsheet_text(value)
    return value
