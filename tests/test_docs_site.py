"""The documentation site and the links of the README and docs/.

The site (``mkdocs.yml``) is built with warnings as errors and its HTML is checked: every public
name of the API reference is there with its docstring, every README section is on a page, nothing
is loaded from the network. The links of README.md and docs/**/*.md must point to files inside
the repository that exist, and to headings that exist.
"""

from __future__ import annotations

import ast
import html
import importlib
import importlib.util
import inspect
import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"
PACKAGE = REPO / "src" / "vgtarm"

FENCE = re.compile(r"^\s*(```|~~~)")
INLINE_CODE = re.compile(r"(`+)(?:(?!\1).)+?\1")
INLINE_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
REFERENCE_DEFINITION = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+.*)?$")
HTML_LINK = re.compile(r"<(?:a|img)\s[^>]*?(?:href|src)\s*=\s*[\"']([^\"']+)[\"']", re.IGNORECASE)
SCHEME = re.compile(r"^[a-z][a-z0-9+.-]*:", re.IGNORECASE)

ALLOWED_EXTERNAL: frozenset[str] = frozenset()
"""External addresses a README or docs page may link to: none (issue 27: no link points outside
the repository). Add one here only when a page cannot do without it."""


# --- links --------------------------------------------------------------------------------------


def github_slug(heading: str) -> str:
    """The anchor GitHub (and MkDocs' toc for these pages) gives a Markdown heading."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip())  # a link's text only
    text = re.sub(r"[`*_]", "", text).lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def markdown_lines(text: str) -> list[tuple[int, str]]:
    """The lines outside fenced code blocks, with inline code spans blanked, numbered from 1."""
    out, in_fence = [], False
    for number, line in enumerate(text.splitlines(), start=1):
        if FENCE.match(line):
            in_fence = not in_fence
            continue
        if not in_fence:
            out.append((number, INLINE_CODE.sub("", line)))
    return out


def anchors(path: Path) -> set[str]:
    """The heading anchors of a Markdown file, duplicates numbered as GitHub does."""
    seen: dict[str, int] = {}
    found = set()
    for _, line in markdown_lines(path.read_text()):
        match = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if match:
            slug = github_slug(match[1])
            count = seen.get(slug, 0)
            seen[slug] = count + 1
            found.add(slug if count == 0 else f"{slug}-{count}")
    return found


def links(path: Path) -> list[tuple[int, str]]:
    """Every link and image target of a Markdown file: inline, reference definitions and HTML."""
    found: list[tuple[int, str]] = []
    for number, line in markdown_lines(path.read_text()):
        for pattern in (INLINE_LINK, REFERENCE_DEFINITION, HTML_LINK):
            found.extend((number, match[1]) for match in pattern.finditer(line))
    return found


def link_problems(path: Path, root: Path = REPO) -> list[str]:
    """What is wrong with the links of ``path``: a target outside ``root``, missing, a missing
    heading, or an external address not in :data:`ALLOWED_EXTERNAL`."""
    problems = []
    root = root.resolve()
    for number, target in links(path):
        where = f"{path.relative_to(root)}:{number}: {target!r}"
        if SCHEME.match(target) or target.startswith("//"):
            if target not in ALLOWED_EXTERNAL:
                problems.append(f"{where} points outside the repository")
            continue
        file_part, _, fragment = target.partition("#")
        file_part = file_part.partition("?")[0]
        if file_part.startswith("/"):
            problems.append(f"{where} is an absolute path; write it relative to the file")
            continue
        resolved = (path.parent / file_part).resolve() if file_part else path.resolve()
        if not resolved.is_relative_to(root):
            problems.append(f"{where} leaves the repository")
            continue
        if not resolved.exists():
            problems.append(f"{where} does not exist")
            continue
        if fragment and resolved.suffix == ".md" and fragment not in anchors(resolved):
            problems.append(f"{where}: {resolved.relative_to(root)} has no heading #{fragment}")
    return problems


def markdown_files() -> list[Path]:
    return [REPO / "README.md", *sorted(DOCS.rglob("*.md"))]


@pytest.mark.parametrize("path", markdown_files(), ids=lambda p: str(p.relative_to(REPO)))
def test_links_stay_in_the_repository_and_exist(path: Path) -> None:
    assert link_problems(path) == []


def test_link_check_finds_each_kind_of_bad_link(tmp_path: Path) -> None:
    """The checker itself: each kind of bad link is reported, good ones are not."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "other.md").write_text("# Other\n\n## A heading\n")
    (tmp_path / "docs" / "image.png").write_bytes(b"")
    page = tmp_path / "README.md"
    page.write_text(
        "# Title\n\n"
        "[ok](docs/other.md) [ok](docs/other.md#a-heading) [ok](#title) ![ok](docs/image.png)\n"
        "[up](../outside.md) [gone](docs/missing.md) [web](https://example.org/x) ![pic](../x.png)\n"
        "[bad anchor](docs/other.md#nowhere) [abs](/etc/passwd)\n"
        "[ref]: docs/missing-too.md\n"
        '<img src="../escape.png">\n'
        "`[in code](../not-a-link.md)`\n\n"
        "```\n[in a block](../not-a-link.md)\n```\n"
    )
    problems = link_problems(page, root=tmp_path)
    expected = [
        "'../outside.md' leaves",
        "'docs/missing.md' does not exist",
        "'https://example.org/x' points outside",
        "'../x.png' leaves",
        "has no heading #nowhere",
        "'/etc/passwd' is an absolute path",
        "'docs/missing-too.md' does not exist",
        "'../escape.png' leaves",
    ]
    assert len(problems) == len(expected), problems
    for part, problem in zip(expected, problems, strict=True):
        assert part in problem


def test_no_pointer_to_the_spec_folder() -> None:
    """``shared/spec`` is outside the repository; its content lives in docs/conventions.md."""
    files = [*markdown_files(), *PACKAGE.rglob("*.py"), *(REPO / "examples").rglob("*.toml")]
    assert [str(f.relative_to(REPO)) for f in files if "shared/spec" in f.read_text()] == []


# --- the docs extra -----------------------------------------------------------------------------


def test_docs_extra_is_declared_with_bounds_and_in_the_test_extra() -> None:
    extras = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    names = {re.split(r"[\[<>=!~ ]", requirement, maxsplit=1)[0]: requirement for requirement in extras["docs"]}
    assert set(names) == {"mkdocs", "mkdocs-material", "mkdocstrings"}
    assert all("<" in requirement and ">=" in requirement for requirement in names.values())
    assert "mkdocstrings[python]" in names["mkdocstrings"]
    (test_self,) = [r for r in extras["test"] if r.startswith("vgtarm[")]
    assert "docs" in test_self[len("vgtarm[") : -1].split(",")
    requirements = pytest.importorskip("packaging.requirements")
    metadata = importlib.import_module("importlib.metadata")
    for requirement in names.values():
        parsed = requirements.Requirement(requirement)
        try:
            installed = metadata.version(parsed.name)
        except metadata.PackageNotFoundError:
            continue
        assert parsed.specifier.contains(installed, prereleases=True), (requirement, installed)


# --- the site -----------------------------------------------------------------------------------


def _have_mkdocs() -> bool:
    return importlib.util.find_spec("mkdocs") is not None


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if not _have_mkdocs():
        pytest.skip('mkdocs is not installed (it comes with the docs extra: pip install -e ".[docs]")')
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    command = [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)]
    done = subprocess.run(command, cwd=REPO, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"mkdocs build --strict failed:\n{done.stdout}\n{done.stderr}"
    return out


def page_text(path: Path) -> str:
    """The visible text of an HTML page, lowercase, every run of non-alphanumerics one space."""
    text = re.sub(r"<(script|style)\b.*?</\1>", " ", path.read_text(), flags=re.DOTALL)
    return normalise(html.unescape(re.sub(r"<[^>]+>", " ", text)))


def normalise(text: str) -> str:
    return " ".join(re.sub(r"[^0-9a-z]+", " ", text.lower()).split())


def docstring_opening(doc: str) -> str:
    """The first sentence of a docstring's first paragraph as the site shows it, normalised."""
    paragraph = doc.strip().split("\n\n", 1)[0]
    paragraph = re.sub(r":[a-z]+:`~[\w.]*?(\w+)`", r"\1", paragraph)  # :func:`~a.b.c` -> c
    paragraph = re.sub(r":[a-z]+:`([^`]+)`", r"\1", paragraph)
    sentence = re.split(r"(?<=[.:;])\s", " ".join(paragraph.split()), maxsplit=1)[0]
    return normalise(sentence)


def documented_modules() -> dict[str, Path]:
    """Module -> the API page that documents it (a ``::: module`` line of docs/api/*.md)."""
    found = {}
    for page in sorted((DOCS / "api").glob("*.md")):
        for match in re.finditer(r"^:::\s*([\w.]+)\s*$", page.read_text(), re.MULTILINE):
            found[match[1]] = page
    return found


def public_names(module_name: str) -> list[str]:
    module = importlib.import_module(module_name)
    names = getattr(module, "__all__", None)
    if names is None:
        names = [
            name
            for name, value in vars(module).items()
            if not name.startswith("_") and getattr(value, "__module__", None) == module_name
        ]
    return list(names)


def constant_docstring(name: str) -> str | None:
    """The docstring of a module constant ``name`` of the package, read from its source: the
    string right after its assignment, else the ``#:`` comments right above it (None if neither,
    or if several modules assign it)."""
    found = []
    for file in PACKAGE.rglob("*.py"):
        source = file.read_text()
        if name not in source:
            continue
        body = ast.parse(source).body
        for index, node in enumerate(body):
            targets = node.targets if isinstance(node, ast.Assign) else [getattr(node, "target", None)]
            if not any(isinstance(t, ast.Name) and t.id == name for t in targets):
                continue
            after = body[index + 1] if index + 1 < len(body) else None
            if (
                isinstance(after, ast.Expr)
                and isinstance(after.value, ast.Constant)
                and isinstance(after.value.value, str)
            ):
                found.append(after.value.value)
                continue
            lines, number = source.splitlines(), node.lineno - 2
            comments: list[str] = []
            while number >= 0 and lines[number].lstrip().startswith("#:"):
                comments.insert(0, lines[number].lstrip()[2:].strip())
                number -= 1
            if comments:
                found.append("\n".join(comments))
    return found[0] if len(found) == 1 else None


def test_every_public_package_has_an_api_page() -> None:
    """The package itself, each public subpackage (the command line ``app`` is the guide's) and
    the public modules the guide uses (``paths``, ``ga``)."""
    packages = {
        f"vgtarm.{p.name}"
        for p in PACKAGE.iterdir()
        if (p / "__init__.py").exists() and not p.name.startswith("_") and p.name != "app"
    }
    assert {"vgtarm", "vgtarm.paths", "vgtarm.ga", *packages} <= set(documented_modules())


@pytest.mark.parametrize("module_name", sorted(documented_modules()))
def test_api_page_renders_every_public_name_with_its_docstring(site: Path, module_name: str) -> None:
    page = documented_modules()[module_name]
    built = site / "api" / page.with_suffix(".html").name
    source = built.read_text()
    text = page_text(built)
    module = importlib.import_module(module_name)
    if module.__doc__:
        assert docstring_opening(module.__doc__) in text
    names = public_names(module_name)
    assert names, module_name
    checked = 0
    for name in names:
        value = getattr(module, name)
        if inspect.ismodule(value):  # a subpackage named by the package (vgtarm.paths): its own page
            assert f"{module_name}.{name}" in documented_modules(), f"{module_name}.{name} has no API page"
            continue
        assert f'id="{module_name}.{name}"' in source, f"{module_name}.{name} is not on {built.name}"
        if isinstance(value, type) or inspect.isroutine(value):
            doc = value.__doc__
            if doc is not None and doc.startswith(f"{value.__name__}("):  # a dataclass's generated one
                doc = None
        else:
            doc = constant_docstring(name)
        if doc:
            opening = docstring_opening(doc)
            assert opening, (module_name, name, doc)
            assert opening in text, f"the docstring of {module_name}.{name} is not on {built.name}: {opening!r}"
            checked += 1
    assert checked >= len(names) // 2, f"only {checked} of {len(names)} names of {module_name} have a docstring"


def test_api_reference_links_sphinx_roles(site: Path) -> None:
    """``:func:`solve_point``` in vgtarm.ik's docstring is a link to its entry, not raw text."""
    source = (site / "api" / "ik.html").read_text()
    assert ":func:" not in source and ":class:" not in source
    # to its entry on this page, or to the same function's entry as a name of the package
    link = r'<a [^>]*href="(?:#vgtarm\.ik|index\.html#vgtarm)\.solve_point"[^>]*><code>solve_point</code></a>'
    assert re.search(link, source)


def test_every_readme_section_is_on_the_site(site: Path) -> None:
    headings = [line[3:] for _, line in markdown_lines((REPO / "README.md").read_text()) if line.startswith("## ")]
    assert "Two commands" in headings
    pages = {p: p.read_text() for p in site.glob("*.html")}
    for heading in headings:
        slug = github_slug(heading)
        assert any(f'id="{slug}"' in source for source in pages.values()), heading
    assert 'id="two-commands"' in pages[site / "index.html"]
    assert normalise(".venv/bin/vgtarm reproduce --out results") in page_text(site / "index.html")


def test_site_loads_nothing_from_the_network(site: Path) -> None:
    for page in site.rglob("*.html"):
        source = page.read_text()
        remote = re.findall(r"<(?:script|link|img|iframe)\b[^>]*(?:src|href)=\"(?:https?:)?//[^\"]+\"", source)
        assert remote == [], (page.name, remote)
        assert "fonts.googleapis" not in source and "fonts.gstatic" not in source


def test_shared_attribute_entries_are_split_per_name() -> None:
    """The site's griffe extension gives ``a, b: text`` of an Attributes section one entry per name
    (Google style has one name per entry); other sections and prose are left as they are."""
    spec = importlib.util.spec_from_file_location("sphinx_roles", DOCS / "_hooks" / "sphinx_roles.py")
    if spec is None or spec.loader is None or importlib.util.find_spec("griffe") is None:
        pytest.skip("griffe (the docs extra) is not installed")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    text = (
        "Lead, with a, b: prose.\n\nAttributes:\n    t: times.\n    q, qd: values\n        and rates.\n\n"
        "Args:\n    a, b: kept.\n"
    )
    assert module.split_shared_entries(text).splitlines() == [
        "Lead, with a, b: prose.",
        "",
        "Attributes:",
        "    t: times.",
        "    q: values",
        "        and rates.",
        "    qd: values",
        "        and rates.",
        "",
        "Args:",
        "    a, b: kept.",
    ]
