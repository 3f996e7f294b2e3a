"""The repository is self-contained: the math and the references live in ``docs/``.

Users get only the repository, so no tracked file may point outside it (a specification kept
elsewhere, a path above the work tree, a tracker's item number), the documentation index must
resolve, and the reference list must name every work the code implements or follows.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
THIS = Path(__file__).resolve().relative_to(ROOT).as_posix()

#: What a pointer outside the repository looks like: a path into a specification kept beside
#: the repository, or a tracker's item number ("issue" followed by a number). This file holds
#: examples of both, so the scan skips it.
#: Written in pieces so that this file's own source does not read as such a pointer.
_SPEC_DIR = "/".join(("shared", "spec"))
OUTSIDE = re.compile(
    "|".join([re.escape(_SPEC_DIR), r"\.\./shared", r"\bissue[ -]#?\d+"]), re.IGNORECASE
)

#: Each work ``docs/references.md`` must name: (what it is, strings its entry must contain).
#: Where the copy of a paper the project worked from prints no year (Prosov) or neither authors
#: nor year (the multi-radar velocity paper), its entry is identified by its original title.
WORKS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("Prosov, converted measurements", ("Prosov", "Анализ влияния линеаризации")),
    ("Gorshkov and Zavizhenets 2016", ("Gorshkov", "Zavizhenets", "2016")),
    ("the multi-radar velocity paper", ("повного вектора швидкості",)),
    ("Lerro and Bar-Shalom 1993", ("Lerro", "Bar-Shalom", "1993", "29(3)", "1015–1022")),
    ("Mo et al. 1998", ("Mo", "Song", "Zhou", "Sun", "Bar-Shalom", "1998", "34(3)", "1023–1027")),
    ("Bordonaro et al. 2014", ("Bordonaro", "Willett", "Bar-Shalom", "2014", "50(2)", "1431–1444")),
    ("Duan, Han and Li 2004", ("Duan", "Han", "Li", "2004", "40(4)", "1374–1377")),
    ("FilterPy (Labbe)", ("Labbe", "FilterPy")),
    ("Van der Merwe 2004", ("van der Merwe", "2004")),
)

LINK = re.compile(r"\]\(([^)\s]+)\)")


def tracked_files() -> list[str]:
    """Every file git tracks (the test fails, not skips, where git cannot list them)."""
    git = shutil.which("git")
    assert git, "git is needed to list the tracked files"
    out = subprocess.run(
        [git, "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True
    ).stdout.decode()
    files = [f for f in out.split("\0") if f]
    assert files, "git ls-files listed nothing"
    return files


def outside_references() -> dict[str, list[str]]:
    """Tracked file → its lines (``line N: text``) that point outside the repository."""
    found: dict[str, list[str]] = {}
    for name in tracked_files():
        if name == THIS:
            continue
        path = ROOT / name
        if not path.is_file():  # deleted in the work tree but still tracked
            continue
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:  # binary (e.g. docs/viewer.png)
            continue
        hits = [
            f"line {i}: {line.strip()}"
            for i, line in enumerate(text.splitlines(), 1)
            if OUTSIDE.search(line)
        ]
        if hits:
            found[name] = hits
    return found


def test_pattern_catches_what_it_must() -> None:
    """The scan's pattern matches each kind of outside pointer and not ordinary words."""
    bad_examples = (
        f"see {_SPEC_DIR}/conversion.md",
        "/".join(("..", "shared", "x")),
        " ".join(("Issue", "3")),
        "-".join(("the issue", "2 metrics")),
    )
    for bad in bad_examples:
        assert OUTSIDE.search(bad), bad
    for fine in ("SweepSpec", "shared sites", "the spec of a grid axis", "issues a warning"):
        assert not OUTSIDE.search(fine), fine


def test_no_tracked_file_points_outside_the_repository() -> None:
    found = outside_references()
    listing = "\n".join(f"{name}:\n  " + "\n  ".join(hits) for name, hits in sorted(found.items()))
    assert not found, f"{len(found)} tracked file(s) point outside the repository:\n{listing}"


def _slug(heading: str) -> str:
    """GitHub's anchor for a Markdown heading: lower case, punctuation dropped, spaces → '-'."""
    s = heading.strip().lower()
    s = re.sub(r"[^\w\- ]", "", s)
    return s.replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    text = path.read_text(encoding="utf-8")
    return {_slug(m.group(1)) for m in re.finditer(r"^#+\s+(.*)$", text, re.MULTILINE)}


def _local_links(path: Path) -> list[str]:
    text = path.read_text(encoding="utf-8")
    return [t for t in LINK.findall(text) if not re.match(r"[a-z]+://", t)]


def test_docs_index_links_resolve_and_cover_every_document() -> None:
    index = DOCS / "README.md"
    assert index.is_file(), "docs/README.md (the index) is missing"
    linked = set()
    for target in _local_links(index):
        file = target.split("#", 1)[0]
        assert (DOCS / file).is_file(), f"docs/README.md links to a missing file: {target}"
        linked.add(file)
    documents = {p.name for p in DOCS.glob("*.md")} - {"README.md"}
    assert documents, "docs/ holds no documents"
    assert documents <= linked, f"docs/README.md does not list {sorted(documents - linked)}"


@pytest.mark.parametrize(
    "source", ["README.md", *sorted(f"docs/{p.name}" for p in DOCS.glob("*.md"))]
)
def test_links_between_documents_resolve(source: str) -> None:
    """Every relative link in the README and docs/ reaches a file, and its #anchor a heading."""
    path = ROOT / source
    for target in _local_links(path):
        file, _, anchor = target.partition("#")
        dest = (path.parent / file).resolve() if file else path
        assert dest.exists(), f"{source} links to a missing {target}"
        if anchor and dest.suffix == ".md":
            assert anchor in _anchors(dest), f"{source}: no heading #{anchor} in {file or source}"


def _reference_entries() -> list[str]:
    text = (DOCS / "references.md").read_text(encoding="utf-8")
    return re.split(r"^###\s+", text, flags=re.MULTILINE)[1:]


@pytest.mark.parametrize("work", WORKS, ids=[w[0] for w in WORKS])
def test_references_name_each_work(work: tuple[str, tuple[str, ...]]) -> None:
    """One entry of docs/references.md holds all of the work's identifying strings."""
    label, needles = work
    entries = _reference_entries()
    assert entries, "docs/references.md has no ### entries"
    assert any(all(n in e for n in needles) for e in entries), (
        f"docs/references.md has no entry naming {label} (looked for {needles})"
    )


def test_ci_runs_the_readme_test_command() -> None:
    """``.ci/run`` ends with the README's test command, character for character (the README
    says it runs exactly that)."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    shown = [line.strip() for line in readme if line.startswith("    ") and "pytest" in line]
    assert len(shown) == 1, shown
    ci = [line for line in (ROOT / ".ci" / "run").read_text().splitlines() if line.strip()]
    assert ci[-1].strip() == shown[0]
