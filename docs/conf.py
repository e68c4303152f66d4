"""Sphinx configuration of the ials_zoo documentation site.

Build it with ``python -m sphinx -W --keep-going -b html docs docs/_build/html`` (the
``docs`` extra installs Sphinx, furo and MyST). Warnings are errors: a broken reference or a
docstring that does not parse fails the build. The environment pages are the env classes'
docstrings (autodoc), the guides are Markdown (MyST).
"""

from __future__ import annotations

import ials_zoo

project = "ials_zoo"
author = "the ials_zoo developers"
release = version = ials_zoo.__version__
copyright = "the ials_zoo developers"

extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.napoleon"]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "screenshots", "Thumbs.db", ".DS_Store"]

myst_heading_anchors = 4  # the guides link to their sections by GitHub's anchors
myst_enable_extensions = ["colon_fence"]

autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"members": False}
napoleon_google_docstring = True
napoleon_numpy_docstring = False

html_theme = "furo"
html_title = f"ials_zoo {release}"
html_static_path = ["_static"]
html_css_files = ["custom.css"]  # code blocks wrap (a browser test holds it)
html_show_sourcelink = False


REPOSITORY_FILES = "https://github.com/ials-zoo/ials-zoo/blob/main/"


def _write_board(app, exception) -> None:
    """The leaderboard's web page (``ials_zoo.leaderboard.site``) as ``board.html`` of the
    site, its links to the entries' files pointing at the repository."""
    from pathlib import Path

    from ials_zoo.leaderboard.site import render_site

    board = Path(app.srcdir).parent / "leaderboard"
    if exception is None and app.builder.format == "html" and (board / "results").is_dir():
        render_site(board, out=Path(app.outdir) / "board.html", link_base=REPOSITORY_FILES + "leaderboard/")


def setup(app):
    app.connect("build-finished", _write_board)
