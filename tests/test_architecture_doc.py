"""``docs/architecture.md`` says which files to change to add a method, a scene, a file format,
a panel control or a command; every path its table names must exist in the tree, so the table
cannot drift from the code unnoticed (a file renamed or removed fails this test).

So must every path of the page's other tables and its tree, read the same way: a path is a
code span holding a ``/`` and a file suffix (``core/filters/methods.py``, ``docs/api.md``) or
naming a folder of the repository (``core/filters/``).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "architecture.md"
TABLE_HEADING = "## 7. Where to change what"
#: The kinds of change the table must cover (its first column mentions each).
KINDS = ("method", "scene", "file format", "control of the tuning panel", "command")

SPAN = re.compile(r"`([^`\s]+)`")
PATHLIKE = re.compile(r"(?:[\w.-]+/)+[\w.-]*(?:\.\w+)?")


def _paths(text: str) -> list[str]:
    """The repository paths named in code spans of ``text``."""
    found = []
    for span in SPAN.findall(text):
        if "://" in span or not PATHLIKE.fullmatch(span):
            continue
        found.append(span)
    return found


def _section(text: str, heading: str) -> str:
    start = text.index(heading)
    rest = text[start + len(heading) :]
    end = re.search(r"^## ", rest, re.MULTILINE)
    return rest[: end.start()] if end else rest


def _table_rows(section: str) -> list[list[str]]:
    rows = []
    for line in section.splitlines():
        if line.startswith("|") and not set(line) <= set("|- "):
            rows.append([c.strip() for c in line.strip("|").split("|")])
    return rows[1:]  # the header


def test_the_table_covers_each_kind_of_change() -> None:
    rows = _table_rows(_section(PAGE.read_text(encoding="utf-8"), TABLE_HEADING))
    firsts = " ".join(r[0] for r in rows)
    missing = [k for k in KINDS if k not in firsts]
    assert not missing, f"docs/architecture.md's table has no row for {missing}"
    for row in rows:
        assert _paths(" ".join(row[1:])), f"row {row[0]!r} names no file"


def test_every_path_of_the_table_exists() -> None:
    section = _section(PAGE.read_text(encoding="utf-8"), TABLE_HEADING)
    paths = _paths(section)
    assert len(paths) >= 20, f"the table names only {len(paths)} paths: the reading is broken"
    missing = sorted({p for p in paths if not (ROOT / p).exists()})
    assert not missing, f"docs/architecture.md, {TABLE_HEADING!r}, names missing paths: {missing}"


def test_every_path_of_the_page_exists() -> None:
    text = PAGE.read_text(encoding="utf-8")
    missing = sorted({p for p in _paths(text) if not (ROOT / p).exists()})
    assert not missing, f"docs/architecture.md names missing paths: {missing}"


def _tree_files(text: str) -> list[str]:
    """The files of the page's tree block: each ``name.py`` under its folder line."""
    block = re.search(r"```text\n(.*?)```", text, re.DOTALL)
    assert block, "docs/architecture.md has no tree block"
    files: list[str] = []
    top = ""
    sub = ""
    for line in block.group(1).splitlines():
        m = re.match(r"^(\w[\w.-]*/)", line)
        if m:
            top, sub = m.group(1), ""
            continue
        if line.startswith("     ") and top and sub:  # a folder's continuation line
            files += [top + sub + n for n in re.findall(r"\b([\w-]+\.py)\b", line)]
            continue
        m = re.match(r"^  ([\w.-]+)(/)?\s", line + " ")
        if not m or not top:
            continue
        if m.group(2):
            sub = m.group(1) + "/"
            names = re.findall(r"\b([\w-]+\.py)\b", line[m.end() :])
            files += [top + sub + n for n in names]
        else:
            sub = ""
            files.append(top + m.group(1))
    return files


def test_every_file_of_the_tree_exists() -> None:
    text = PAGE.read_text(encoding="utf-8")
    files = _tree_files(text)
    assert len(files) >= 10, f"the tree lists only {files}"
    missing = sorted(f for f in files if not (ROOT / f).exists())
    assert not missing, f"docs/architecture.md's tree lists missing files: {missing}"


@pytest.mark.parametrize(
    ("text", "paths"),
    [
        (
            "`core/filters/methods.py` and `viz_app/cli/`",
            ["core/filters/methods.py", "viz_app/cli/"],
        ),
        ("`ALL_METHODS`, `radarviz track`, `x/y`", ["x/y"]),
        ("`https://example.org/a.py`", []),
    ],
)
def test_paths_are_read_from_spans(text: str, paths: list[str]) -> None:
    assert _paths(text) == paths


def test_a_missing_path_would_fail() -> None:
    """The existence check is real: a made-up path of the table's form does not exist."""
    assert not (ROOT / "core/filters/no_such_kernel.py").exists()
    assert _paths("| a method | `core/filters/no_such_kernel.py` |") == [
        "core/filters/no_such_kernel.py"
    ]
