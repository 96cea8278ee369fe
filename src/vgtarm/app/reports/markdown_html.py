"""The Markdown that vgtarm's reports write, as HTML: one source for ``report.md`` and ``report.html``.

``report.html`` shows ``report.md``'s text converted here, so the two hold the same sections under
the same headings and cannot drift apart. The parsing is markdown-it-py's (CommonMark with GitHub's
tables, raw HTML off, so any ``<`` in the text is shown as written); this module only adds what the
page needs on top of it:

- every heading gets an element id from its text (:func:`slug`, made unique);
- vgtarm's own HTML can be placed right after a heading (the interactive figures after "Figures");
- the first table can be given an id;
- an image alone in its paragraph is written by a callback (the page inlines its PNG files);
- a link or an image whose destination is not a relative path of the page's folder (a scheme such
  as ``javascript:`` or ``http:``, or a path from ``/``) is not a link: markdown-it shows it as its
  text, so the page links only into its own folder.

User text reaches the Markdown through :mod:`vgtarm.markup` (``md_text``, ``md_cell``,
``md_code``), which escapes every character that could start markup there.
"""

from __future__ import annotations

import html
import re
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache

from markdown_it import MarkdownIt
from markdown_it.renderer import RendererHTML
from markdown_it.token import Token

__all__ = ["Heading", "headings", "slug", "to_html"]

#: markdown-it's HTML renderer, for an image's alt text as the characters it shows.
_RENDERER = RendererHTML()

#: A link destination the page may hold: a relative path (percent-encoded), no scheme, not from ``/``.
_RELATIVE = re.compile(r"^(?![A-Za-z][A-Za-z0-9+.-]*:)(?!/)[A-Za-z0-9%._~!$&'()*+,;=:@/-]+$")


@dataclass(frozen=True)
class Heading:
    """A heading of the document: level (1 to 6), its text as shown, and its element id."""

    level: int
    text: str
    id: str


def slug(text: str) -> str:
    """An element id from a heading's text: lower-case letters and digits joined by ``-``."""
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "section"


@cache
def _parser() -> MarkdownIt:
    parser = MarkdownIt("commonmark", {"html": False, "xhtmlOut": False}).enable("table")
    parser.validateLink = lambda url: bool(_RELATIVE.match(url))  # type: ignore[method-assign]
    return parser


def to_html(
    markdown: str,
    *,
    image: Callable[[str, str], str] | None = None,
    after_heading: dict[str, str] | None = None,
    first_table_id: str | None = None,
) -> str:
    """``markdown`` as HTML (see the module's docstring).

    Args:
        markdown: the document.
        image: the HTML of an image alone in its paragraph from its alt text (the characters it
            shows) and its file name (percent-encoded as in a link); default markdown-it's ``<img>``.
        after_heading: HTML (trusted: vgtarm's own) to place right after the heading of that
            text, e.g. the interactive figures after "Figures".
        first_table_id: the ``id`` of the first table.
    """
    parser = _parser()
    tokens, _ = _convert(markdown, image, after_heading or {}, first_table_id)
    return parser.renderer.render(tokens, parser.options, {})


def headings(markdown: str) -> list[Heading]:
    """The headings of ``markdown`` as :func:`to_html` writes them (text as shown, ids)."""
    return _convert(markdown, None, {}, None)[1]


def _raw(content: str) -> Token:
    """A token the renderer writes as it is (vgtarm's own HTML)."""
    return Token("html_block", "", 0, content=content + "\n")


def _convert(
    markdown: str,
    image: Callable[[str, str], str] | None,
    after: dict[str, str],
    first_table_id: str | None,
) -> tuple[list[Token], list[Heading]]:
    parser = _parser()
    tokens = parser.parse(markdown)
    out: list[Token] = []
    found: list[Heading] = []
    ids: set[str] = set()
    tables = 0
    k = 0
    while k < len(tokens):
        token = tokens[k]
        if token.type == "heading_open":
            inline, close = tokens[k + 1], tokens[k + 2]
            shown = html.unescape(re.sub(r"<[^>]*>", "", parser.renderer.render([inline], parser.options, {})))
            ident = _unique(slug(shown), ids)
            token.attrSet("id", ident)
            found.append(Heading(int(token.tag[1]), shown, ident))
            out += [token, inline, close]
            if shown in after:
                out.append(_raw(after[shown]))
            k += 3
            continue
        if token.type == "table_open":
            if tables == 0 and first_table_id:
                token.attrSet("id", first_table_id)
            tables += 1
        if image is not None and token.type == "paragraph_open" and _lone_image(tokens[k + 1]):
            picture = tokens[k + 1].children[0]  # type: ignore[index]
            alt = _RENDERER.renderInlineAsText(picture.children or [], parser.options, {})
            out.append(_raw(image(alt, str(picture.attrGet("src")))))
            k += 3
            continue
        out.append(token)
        k += 1
    return out, found


def _lone_image(inline: Token) -> bool:
    children = inline.children or []
    return inline.type == "inline" and len(children) == 1 and children[0].type == "image"


def _unique(ident: str, seen: set[str]) -> str:
    candidate, n = ident, 1
    while candidate in seen:
        n += 1
        candidate = f"{ident}-{n}"
    seen.add(candidate)
    return candidate
