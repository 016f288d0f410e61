"""Sphinx configuration of sb3-er's documentation: MyST Markdown, autodoc, the CLI reference from the argparse tree and
the results pages generated from results/measured/ (see _ext/sb3er_docs.py). ``make docs`` builds it with -W."""

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS / "_ext"))

import sb3_er  # noqa: E402

project = "sb3-er"
author = "sb3-er contributors"
copyright = "sb3-er contributors"
release = version = sb3_er.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinxarg.ext",
    "sb3er_docs",
    "sb3er_benchmarks",
]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
# _notes holds text the pages include; the generated results pages are written into results/ at every build.
exclude_patterns = ["_build", "_notes", "_ext", "Thumbs.db", ".DS_Store"]
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3
# The included summaries are written by sb3-er's own reports, whose headings start at their own level.
suppress_warnings = ["myst.header"]

autodoc_member_order = "bysource"
autodoc_typehints = "description"
# A class shows its constructor signature in its heading (SB3's pages do too): every parameter with its default.
autodoc_class_signature = "mixed"
autodoc_default_options = {"show-inheritance": True}

html_theme = "sphinx_rtd_theme"
html_title = f"sb3-er {release}"
html_theme_options = {"navigation_depth": 3}
# Wide tables wrap their cells instead of hiding columns (see _static/sb3er.css).
html_static_path = ["_static"]
html_css_files = ["sb3er.css"]
