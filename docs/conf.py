"""Sphinx configuration of the mjed-verify documentation (built by `make docs`, offline)."""

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))  # the project's packages, for autodoc and the CLI page
sys.path.insert(0, str(HERE / "_ext"))

project = "mjed-verify"
author = "the mjed-verify authors"
copyright = "the mjed-verify authors"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "site_generation",  # docs/_ext: CLI and API pages, executed tutorials, local MathJax
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "_ext", "tutorials/*.py", "**/.ipynb_checkpoints"]

myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence"]
myst_heading_anchors = 3

autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_mock_imports = []
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_ivar = True  # "Attributes:" as fields, so a property is not described twice

# MathJax 2 from Debian's libjs-mathjax, copied into _static/mathjax by site_generation:
# a relative path is resolved against _static, so no page loads anything from the network.
mathjax_path = "mathjax/MathJax.js?config=TeX-AMS_CHTML"
# Only Sphinx's math elements are typeset (not code that happens to contain "\\("); MyST's
# own MathJax settings are for MathJax 3 and would mark every section "ignore" for MathJax 2.
mathjax2_config = {
    "tex2jax": {
        "inlineMath": [["\\(", "\\)"]],
        "displayMath": [["\\[", "\\]"]],
        "processEscapes": True,
        "ignoreClass": "document",
        "processClass": "math",
    },
    "CommonHTML": {"linebreaks": {"automatic": True}},
    "messageStyle": "none",
}
myst_update_mathjax = False

html_theme = "sphinx_rtd_theme"
html_title = "mjed-verify"
html_static_path = []
html_show_sourcelink = False
html_theme_options = {"navigation_depth": 3, "collapse_navigation": False}
