"""The repository documents itself: references resolve inside it.

* No file names a document the repository does not ship, and no file points to a path
  outside the repository (an absolute workspace path, or a ``../`` path that leaves the
  repository or names nothing; test modules are spared the latter, since they build
  such paths on purpose as bad input).
* Every ``docs/<page>.md#<anchor>`` written anywhere (code, tests, README, benchmarks)
  names an existing page and one of its headings, and every link inside ``docs/``
  resolves the same way.

Anchors are made from headings as GitHub makes them: lower case, punctuation other than
``-`` and ``_`` dropped, spaces turned into ``-``, repeats numbered ``-1``, ``-2``, ...
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"

# Names of documents that are not part of the repository.
FOREIGN_DOCUMENTS = re.compile(r"\b(CONTRACT|METHODS)\.md\b")
# Absolute paths into a workspace or a home folder.
ABSOLUTE_PATH = re.compile(r"(?<![\w.~-])/(work|home|root|Users|mnt|shared)/[\w.-]")
# Relative paths that start by climbing out of a folder.
PARENT_PATH = re.compile(r"(?<![\w./-])((?:\.\./)+[\w.-][\w./-]*)")
# Embedded data (images in the shipped reports) is not text to search.
DATA_URI = re.compile(r"data:[\w/+.-]+;base64,[A-Za-z0-9+/=]+")
DOCS_REFERENCE = re.compile(r"\bdocs/([\w-]+\.md)(?:#([\w-]+))?")
MARKDOWN_LINK = re.compile(r"\]\(([^)\s]*)\)")
SKIPPED_FOLDERS = {".git", "__pycache__", ".pytest_cache", ".ruff_cache", "build", "dist"}


def repository_files() -> list[Path]:
    """Every file of the repository: tracked and untracked but not ignored, without .git."""
    try:
        listed = subprocess.run(
            ["git", "ls-files", "--cached", "--others", "--exclude-standard", "-z"],
            cwd=ROOT, capture_output=True, check=True).stdout.decode()
        paths = [ROOT / name for name in listed.split("\0") if name]
    except (OSError, subprocess.CalledProcessError):
        paths = [p for p in ROOT.rglob("*")
                 if not SKIPPED_FOLDERS & set(p.relative_to(ROOT).parts)
                 and not any(part.endswith(".egg-info") for part in p.parts)]
    return sorted(p for p in paths if p.is_file())


def text_of(path: Path) -> str | None:
    """The file as text without embedded data, or None for a binary file."""
    data = path.read_bytes()
    if b"\0" in data:
        return None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        return None
    return DATA_URI.sub("", text)


def texts() -> dict[Path, str]:
    out = {}
    for path in repository_files():
        text = text_of(path)
        if text is not None:
            out[path] = text
    return out


def slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading's text."""
    text = re.sub(r"[`*_]{2,}|`", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """Anchors of every heading of a Markdown page (fenced code is not a heading)."""
    found: set[str] = set()
    counts: dict[str, int] = {}
    fenced = False
    for line in page.read_text().splitlines():
        if line.startswith("```"):
            fenced = not fenced
            continue
        match = re.match(r"#{1,6}\s+(.*?)\s*#*\s*$", line)
        if fenced or not match:
            continue
        base = slug(match.group(1))
        count = counts.get(base, 0)
        counts[base] = count + 1
        found.add(base if count == 0 else f"{base}-{count}")
    return found


def line_of(text: str, index: int) -> int:
    return text.count("\n", 0, index) + 1


def test_the_slug_follows_github():
    assert slug("Modified DH") == "modified-dh"
    assert slug("Cross-bar calibration") == "cross-bar-calibration"
    assert slug("result.json additions") == "resultjson-additions"
    assert slug("kind: cross_bar") == "kind-cross_bar"


def test_the_documentation_pages_exist():
    for name in ("README.md", "conventions.md", "formats.md", "methods.md", "usage.md",
                 "measured.md", "layout.md", "delivery.md"):
        assert (DOCS / name).is_file(), name


def test_no_file_names_a_document_the_repository_does_not_ship():
    offending = [f"{path.relative_to(ROOT)}:{line_of(text, m.start())}: {m.group(0)}"
                 for path, text in texts().items() for m in FOREIGN_DOCUMENTS.finditer(text)]
    assert not offending, "\n".join(offending)


def test_no_file_points_outside_the_repository():
    offending = []
    for path, text in texts().items():
        for match in ABSOLUTE_PATH.finditer(text):
            offending.append(f"{path.relative_to(ROOT)}:{line_of(text, match.start())}: "
                             f"absolute path {text[match.start():match.start() + 40]!r}")
        if path.parent == ROOT / "tests" and path.suffix == ".py":
            continue  # tests write paths that leave a folder on purpose, as bad input
        for match in PARENT_PATH.finditer(text):
            target = (path.parent / match.group(1).split("#")[0]).resolve()
            inside = target == ROOT or ROOT in target.parents
            if not inside or not target.exists():
                offending.append(f"{path.relative_to(ROOT)}:{line_of(text, match.start())}: "
                                 f"{match.group(1)!r} is not a path in the repository")
    assert not offending, "\n".join(offending)


def test_docs_references_in_the_repository_resolve():
    pages = {p.name: anchors(p) for p in DOCS.glob("*.md")}
    checked, broken = 0, []
    for path, text in texts().items():
        for match in DOCS_REFERENCE.finditer(text):
            page, anchor = match.groups()
            where = f"{path.relative_to(ROOT)}:{line_of(text, match.start())}: {match.group(0)}"
            checked += 1
            if page not in pages:
                broken.append(f"{where}: no page docs/{page}")
            elif anchor is not None and anchor not in pages[page]:
                broken.append(f"{where}: no heading #{anchor}; headings: {sorted(pages[page])}")
    assert checked >= 20  # the code does point into docs/
    assert not broken, "\n".join(broken)


@pytest.mark.parametrize("page", sorted(p.name for p in DOCS.glob("*.md")))
def test_links_inside_docs_resolve(page):
    source = DOCS / page
    broken = []
    for match in MARKDOWN_LINK.finditer(source.read_text()):
        target = match.group(1)
        if re.match(r"[a-z]+:", target):
            continue  # a web address
        file_part, _, anchor = target.partition("#")
        linked = (source.parent / file_part).resolve() if file_part else source
        if not linked.exists():
            broken.append(f"{target}: no file {linked}")
        elif anchor and linked.suffix == ".md" and anchor not in anchors(linked):
            broken.append(f"{target}: no heading #{anchor} in {linked.name}")
    assert not broken, "\n".join(broken)


def test_the_checks_catch_what_they_look_for(tmp_path):
    """The patterns find a foreign document, an outside path and a stale anchor."""
    assert FOREIGN_DOCUMENTS.search("see " + "CONTRACT" + ".md for the format")
    assert ABSOLUTE_PATH.search('DATA = Path("/' + 'work/shared/data")')
    assert not ABSOLUTE_PATH.search("robocal_casadi/data/README.md and https://a.b/home/x")
    outside = "../" + "shared/data"
    assert PARENT_PATH.search(f"in {outside} (or").group(1) == outside
    page = tmp_path / "page.md"
    page.write_text("# Title\n## Modified DH\n```\n# not a heading\n```\n## Modified DH\n")
    assert anchors(page) == {"title", "modified-dh", "modified-dh-1"}


# ----------------------------------------------------------------------------- README and docs

FRONT_PAGES = [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]
FENCE = re.compile(r"^```[^\n]*\n(.*?)^```", re.MULTILINE | re.DOTALL)
INLINE_CODE = re.compile(r"(?<!`)`(robocal [^`]+)`(?!`)")


def command_lines(text: str) -> list[str]:
    """Every ``robocal ...`` command line of the text's fenced blocks (continuation lines
    joined, ``$NAME`` expanded from ``NAME="..."`` set in the same block, comments and
    printed ``robocal VERB: ...`` lines left out) and of its inline code."""
    found = []
    for block in FENCE.findall(text):
        block = block.replace("\\\n", " ")
        variables = dict(re.findall(r'^(\w+)="([^"]*)"', block, re.MULTILINE))
        for line in block.splitlines():
            line = line.split("  #", 1)[0].strip().removeprefix("$ ")
            for name, value in variables.items():
                line = line.replace(f"${name}", value)
            if line.startswith("robocal ") and not line.split()[1].endswith(":"):
                found.append(" ".join(line.split()))  # not a printed "robocal VERB: ..."
    found += [" ".join(m.group(1).split()) for m in INLINE_CODE.finditer(text)
              if not m.group(1).split()[1].endswith(":")]
    return found


def unknown_in(line: str, parsers: dict) -> list[str]:
    """What of a ``robocal`` command line the command line does not know: the verb, or
    any ``--option`` the verb does not take. Placeholders (``...``, ``DIR``) are left
    alone: the line is checked, not run."""
    words = line.replace("[", " ").replace("]", " ").replace("|", " ").split()
    verb = words[1] if len(words) > 1 else ""
    if verb.startswith("--"):
        return [] if verb in ("--version", "--help") else [verb]
    if verb not in parsers:
        return [f"verb {verb!r}"]
    known = parsers[verb]._option_string_actions
    return [w for w in words[2:] if w.startswith("--") and w.split("=")[0] not in known]


def verb_parsers() -> dict:
    from robocal_casadi.cli import build_parser

    parser = build_parser()
    action = next(a for a in parser._actions if a.dest == "verb")
    return dict(action.choices)


@pytest.mark.parametrize("page", FRONT_PAGES, ids=lambda p: p.name)
def test_command_lines_name_verbs_and_options_that_exist(page):
    parsers = verb_parsers()
    lines = command_lines(page.read_text())
    stale = [f"{line}: {unknown_in(line, parsers)}" for line in lines
             if unknown_in(line, parsers)]
    assert not stale, "\n".join(stale)


def test_the_readme_and_usage_show_command_lines():
    assert len(command_lines((ROOT / "README.md").read_text())) >= 10
    assert len(command_lines((DOCS / "usage.md").read_text())) >= 5


def test_the_readme_links_resolve():
    source = ROOT / "README.md"
    broken = []
    for match in MARKDOWN_LINK.finditer(source.read_text()):
        target = match.group(1)
        if re.match(r"[a-z]+:", target):
            continue
        file_part, _, anchor = target.partition("#")
        linked = (source.parent / file_part).resolve() if file_part else source
        if not linked.exists():
            broken.append(f"{target}: no file {linked}")
        elif anchor and linked.suffix == ".md" and anchor not in anchors(linked):
            broken.append(f"{target}: no heading #{anchor} in {linked.name}")
    assert not broken, "\n".join(broken)


def test_the_command_check_catches_a_stale_line():
    parsers = verb_parsers()
    text = ("```bash\nX=\"--seed 1\"\nrobocal simulate --kind cross_bar $X \\\n"
            "    --out bar  # note\nrobocal calibrat bar/dataset.yaml\n```\n"
            "and `robocal fk ROBOT.yaml J.csv --out P.csv --with-efects`")
    lines = command_lines(text)
    assert lines[0] == "robocal simulate --kind cross_bar --seed 1 --out bar"
    assert [unknown_in(line, parsers) for line in lines] == [
        [], ["verb 'calibrat'"], ["--with-efects"]]
