"""Sphinx configuration: the reference documentation built from the docstrings, and the
mathematics pages of this folder (Markdown, through myst-parser).

Build it with ``python -m sphinx -W -b html docs build/docs`` (the README says more);
``tests/test_docs_build.py`` runs that build with warnings as errors.
"""

from __future__ import annotations

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

# Markdown: $…$ and $$…$$ are math (MathJax); headings get anchors for the pages' links.
myst_enable_extensions = ["dollarmath", "amsmath"]
myst_heading_anchors = 3

html_theme = "alabaster"
html_title = "radarviz"
