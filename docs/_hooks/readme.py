"""MkDocs hook of the documentation site: the README's guides, placed on the site's pages.

README.md stays the front door and the one copy of the user guides; the site shows the same text
split over pages, never a second copy that could drift. A page asks for README text with a
marker, a line holding only a link to the README (so that on GitHub the page links to the text):

- ``[README: intro](../README.md)``: the text between the README's title and its first ``##``;
- ``[README: Two commands](../README.md#two-commands)``: the ``##`` section of that title, with
  its subsections (raised one level when the page's own title is the section's);
- ``[README: the other sections](../README.md)``: every ``##`` section that no page asks for, in
  README order, so that a section added to the README later is never missing from the site.

The README's links are written from the repository root; on the site they are rewritten: a file
under ``docs/`` becomes a link relative to the page, ``#anchor`` points to the page that now
holds that heading, and a link to a file outside ``docs/`` (which the site does not publish)
keeps its text only. A docs page's own links to ``../README.md#anchor`` go to the page that
holds that heading. A marker naming no README section, two pages asking for the same section, or
a section on no page is logged as a warning, which ``mkdocs build --strict`` makes an error.

Used only by ``mkdocs.yml`` (``hooks``); not part of the package.
"""

from __future__ import annotations

import logging
import posixpath
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

log = logging.getLogger("mkdocs.hooks.readme")

MARKER = re.compile(r"^\[README: (?P<name>[^\]]+)\]\(\.\./README\.md(?:#[\w-]*)?\)\s*$", re.MULTILINE)
"""A page's request for README text, alone on its line."""
LINK = re.compile(r"(?P<bang>!?)\[(?P<text>[^\]]*)\]\((?P<target>[^)\s]+)(?P<title>\s+\"[^\"]*\")?\)")
"""An inline Markdown link or image: ``[text](target "title")``."""
FENCE = re.compile(r"^\s*(```|~~~)")
INTRO = "intro"
REST = "the other sections"
REST_MARKER = f"[README: {REST}](../README.md)"


def slug(heading: str) -> str:
    """The anchor of a heading, as GitHub and MkDocs' ``toc`` make it for these headings."""
    text = re.sub(r"[`*_]", "", heading.strip()).lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return re.sub(r"\s", "-", text.strip())


@dataclass
class Readme:
    """The README cut at its ``##`` headings, and which page shows each part."""

    intro: str = ""
    sections: dict[str, str] = field(default_factory=dict)
    anchors: dict[str, str] = field(default_factory=dict)  # anchor -> part name
    placed: dict[str, str] = field(default_factory=dict)  # part name -> page (docs-relative)


_STATE: dict[str, Any] = {}


def split_readme(text: str) -> Readme:
    """Cut the README at its level-2 headings outside code blocks; drop its level-1 title."""
    readme = Readme()
    part, in_fence = INTRO, False
    lines: list[str] = []
    for line in text.splitlines():
        if FENCE.match(line):
            in_fence = not in_fence
        if not in_fence and line.startswith("## "):
            _store(readme, part, lines)
            part, lines = line[3:].strip(), []
        elif not in_fence and part == INTRO and line.startswith("# "):
            continue
        if not in_fence and re.match(r"^#{2,6} ", line):
            readme.anchors.setdefault(slug(line.lstrip("#")), part)
        lines.append(line)
    _store(readme, part, lines)
    return readme


def _store(readme: Readme, part: str, lines: list[str]) -> None:
    text = "\n".join(lines).strip("\n") + "\n"
    if part == INTRO:
        readme.intro = text
    else:
        readme.sections[part] = text


def raise_headings(section: str) -> str:
    """A section shown on a page whose title is its own: its heading dropped, the others raised
    one level (``###`` becomes ``##``), code blocks untouched."""
    out, in_fence = [], False
    for line in section.splitlines()[1:]:
        if FENCE.match(line):
            in_fence = not in_fence
        out.append(line[1:] if not in_fence and re.match(r"^#{3,6} ", line) else line)
    return "\n".join(out).strip("\n") + "\n"


def on_config(config: Any, **kwargs: Any) -> Any:
    root = Path(config.config_file_path).resolve().parent
    readme_path = root / "README.md"
    _STATE.update(root=root, docs=Path(config.docs_dir).resolve(), readme=split_readme(readme_path.read_text()))
    return config


def on_files(files: Any, config: Any, **kwargs: Any) -> Any:
    """Find every page's markers first, so links between README parts know their pages."""
    readme: Readme = _STATE["readme"]
    readme.placed.clear()
    rest_page = None
    for file in files.documentation_pages():
        text = Path(file.abs_src_path).read_text()
        for match in MARKER.finditer(text):
            name = match["name"]
            if name == REST:
                if rest_page is not None:
                    log.warning("README sections: '*' is asked for by both %s and %s", rest_page, file.src_uri)
                rest_page = file.src_uri
                continue
            if name != INTRO and name not in readme.sections:
                log.warning(
                    "%s asks for README section %r, which README.md does not have (its sections: %s)",
                    file.src_uri,
                    name,
                    ", ".join(repr(s) for s in readme.sections),
                )
                continue
            if name in readme.placed:
                log.warning("README section %r is asked for by both %s and %s", name, readme.placed[name], file.src_uri)
            readme.placed[name] = file.src_uri
    rest = [name for name in readme.sections if name not in readme.placed]
    if rest and rest_page is None:
        log.warning("README sections %s are on no page of the site (give a page the line %r)", rest, REST_MARKER)
    for name in rest:
        readme.placed[name] = rest_page or ""
    _STATE["rest"] = rest
    return files


def _rewrite_links(text: str, page: str, base: Path) -> str:
    """``text``'s links, written from the folder ``base``, as links from the site page ``page``."""
    readme: Readme = _STATE["readme"]
    root: Path = _STATE["root"]
    docs: Path = _STATE["docs"]
    page_dir = posixpath.dirname(page) or "."
    from_readme = base == root

    def to_page(owner: str, fragment: str) -> str:
        target = "" if owner == page else posixpath.relpath(owner, page_dir)
        return target + (f"#{fragment}" if fragment else "") or "#"

    def replace(match: re.Match[str]) -> str:
        target = match["target"]
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.IGNORECASE):  # http:, mailto: ...
            return match[0]
        path, _, fragment = target.partition("#")
        if not path and not from_readme:
            return match[0]
        resolved = (base / path).resolve() if path else root / "README.md"
        if resolved == root / "README.md":
            owner = readme.placed.get(readme.anchors.get(fragment, ""), "index.md") if fragment else "index.md"
            new = to_page(owner, fragment)
        elif resolved.is_relative_to(docs):
            new = posixpath.relpath(resolved.relative_to(docs).as_posix(), page_dir)
            new += f"#{fragment}" if fragment else ""
        else:
            log.info("link %r leaves docs/: shown as text on %s", target, page)
            return match["text"] if not match["bang"] else ""
        return f"{match['bang']}[{match['text']}]({new}{match['title'] or ''})"

    out, in_fence = [], False
    for line in text.splitlines():
        if FENCE.match(line):
            in_fence = not in_fence
        out.append(line if in_fence else LINK.sub(replace, line))
    return "\n".join(out) + "\n"


def on_page_markdown(markdown: str, page: Any, **kwargs: Any) -> str:
    readme: Readme = _STATE["readme"]
    root: Path = _STATE["root"]
    src = page.file.src_uri
    page_base = Path(page.file.abs_src_path).resolve().parent

    def section(name: str) -> str:
        if name == INTRO:
            return _rewrite_links(readme.intro, src, root)
        if name == REST:
            return "\n".join(_rewrite_links(readme.sections[s], src, root) for s in _STATE["rest"])
        if name not in readme.sections:
            return ""
        text = readme.sections[name]
        if re.search(rf"^# {re.escape(name)}\s*$", markdown, re.MULTILINE):
            text = raise_headings(text)
        return _rewrite_links(text, src, root)

    parts, last = [], 0
    for match in MARKER.finditer(markdown):
        parts.append(_rewrite_links(markdown[last : match.start()], src, page_base))
        parts.append(section(match["name"]))
        last = match.end()
    parts.append(_rewrite_links(markdown[last:], src, page_base))
    return "\n".join(parts)
