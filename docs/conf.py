"""Sphinx configuration: the pages of docs/ (Markdown, through myst-parser) and an
API reference generated from the docstrings (autodoc).  ``make docs`` builds it
with warnings as errors into docs/_build/html, readable offline."""
import sys
from pathlib import Path

# document the checkout this file is in, whatever is installed
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from modelgen.version import __version__  # noqa: E402

project = "modelgen"
author = "the modelgen authors"
release = version = __version__

extensions = ["myst_parser", "sphinx.ext.autodoc"]
source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build"]

# the pages link to each other's sections by their headings (#ball-and-free-joints)
myst_heading_anchors = 3
myst_enable_extensions = ["colon_fence"]

autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": True}

# alabaster ships its own CSS and no web fonts: the HTML reads without a network;
# no math extension, so no MathJax from a CDN
html_theme = "alabaster"
html_title = f"modelgen {release}"
html_static_path = []
html_copy_source = False
