"""Sphinx configuration: the reference documentation built from the docstrings, and the
mathematics pages of this folder (Markdown, through myst-parser).

Build it with ``python -m sphinx -W -b html docs build/docs`` (the README says more);
``tests/test_docs_build.py`` runs that build with warnings as errors.
"""

from __future__ import annotations

import re
from typing import Any

project = "radarviz"
author = "radarviz contributors"
copyright = "radarviz contributors"
release = "0.1.0"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
]
source_suffix = {".md": "markdown"}
root_doc = "index"
# docs/README.md is the folder's index when read as plain files; index.md is Sphinx's.
exclude_patterns = ["README.md", "_build"]

# One docstring style throughout: Google (Args:, Returns:, Raises:, Attributes:).
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_rtype = False
napoleon_use_ivar = True  # Attributes: as fields of the class, not entries of their own
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_default_options = {"members": True, "undoc-members": False}
# The API's modules postpone their annotations (``from __future__ import annotations``), so
# autodoc sees each annotation as the text written in the source; these names are then shown
# as written instead of expanded (numpy's ``ArrayLike`` alone is a union of seven types, which
# buried every argument of ``convert``). Each is a name a reader meets in the docstrings.
autodoc_type_aliases = {
    name: name
    for name in (
        "ArrayLike",
        "NDArray",
        "Columns",
        "StateRow",
        "Progress",
        "Recordable",
        "RowObserver",
    )
}

# Markdown: $…$ and $$…$$ are math (MathJax); headings get anchors for the pages' links.
myst_enable_extensions = ["dollarmath", "amsmath"]
myst_heading_anchors = 3

html_theme = "alabaster"
html_title = "radarviz"


#: An alias inside a union (``ArrayLike | None``) comes out of autodoc as its placeholder's
#: repr, ``TypeAliasForwardRef('ArrayLike') | None``; the alias's name is what the source says.
_ALIAS_REPR = re.compile(r"TypeAliasForwardRef\('(\w+)'\)")


def _alias_names(
    app: Any,
    what: str,
    name: str,
    obj: object,
    options: Any,
    signature: str | None,
    return_annotation: str | None,
) -> tuple[str | None, str | None]:
    """Signatures with every type alias shown by its name (see ``_ALIAS_REPR``)."""

    def named(text: str | None) -> str | None:
        return None if text is None else _ALIAS_REPR.sub(r"\1", text)

    return named(signature), named(return_annotation)


def setup(app: Any) -> None:
    app.connect("autodoc-process-signature", _alias_names)
