"""The reference documentation builds from the docstrings and docs/*.md with warnings as
errors (Sphinx, myst-parser, napoleon: Google-style docstrings), offline."""

from __future__ import annotations

import html
import re
import subprocess
import sys
from pathlib import Path

import radarviz

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def test_every_public_name_is_documented() -> None:
    text = (DOCS / "api.md").read_text(encoding="utf-8")
    documented = set(re.findall(r"\.\. auto\w+:: radarviz\.(\w+)", text))
    assert documented == set(radarviz.__all__), (
        f"missing: {sorted(set(radarviz.__all__) - documented)}, "
        f"not public: {sorted(documented - set(radarviz.__all__))}"
    )


def test_docs_build_without_warnings(tmp_path: Path) -> None:
    out = tmp_path / "html"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "sphinx",
            "-W",
            "--keep-going",
            "-q",
            "-b",
            "html",
            str(DOCS),
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-4000:]
    api = (out / "api.html").read_text(encoding="utf-8")
    for name in radarviz.__all__:
        assert f'id="radarviz.{name}"' in api, f"radarviz.{name} is not in the built page"
    # The docstrings' sections rendered as fields, not as raw "Args:" text.
    assert "Args:" not in api and "Parameters" in api
    for page in ("conversion", "finite_memory", "velocity", "references"):
        assert (out / f"{page}.html").is_file(), page
    check_api_page_reads(api)


def check_api_page_reads(page: str) -> None:
    """The API page as a newcomer reads it: type aliases by their names (numpy's
    ``ArrayLike`` expanded is a union of seven private types, for every argument), the
    package's introduction once, its example whole."""
    text = html.unescape(re.sub(r"<[^>]+>", "", page))
    for expanded in ("_Buffer", "_SupportsArray", "_NestedSequence", "TypeAliasForwardRef"):
        assert expanded not in text, f"{expanded} in the built API page"
    assert "range_m: ArrayLike" in text, "convert's signature does not show ArrayLike"
    intro = "Quantities carry their unit in their name"
    assert text.count(intro) == 1, f"the introduction appears {text.count(intro)} times"
    example = radarviz.__doc__.split("Example::", 1)[1]
    for line in filter(None, (ln.strip() for ln in example.splitlines())):
        assert line in text, f"the example's line {line!r} is not in the built page"
