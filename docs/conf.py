"""Sphinx configuration: the API reference, generated from the docstrings.

Build it with ``make docs`` (``sphinx-build -W --keep-going -b html docs docs/_build/html``);
``tests/test_docs.py`` builds it with warnings as errors.
"""

from __future__ import annotations

import sys
from pathlib import Path

# The installed package (``pip install -e .``) is what autodoc imports; this fallback lets a
# checkout without the install build the pages too.
ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

project = "skillchain_torch"
author = "skillchain_torch developers"
copyright = "skillchain_torch developers"
release = "0.1.0"

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.viewcode",
]

exclude_patterns = ["_build", "GUIDE-DETAILS.md"]
source_suffix = {".rst": "restructuredtext"}
root_doc = "index"

# autodoc: each ``automodule`` names ``:members:`` itself (a package's ``__all__`` where it has
# one). Undocumented public members are listed too (a dataclass's fields, for one); private and
# special members are not. (An option is off by leaving it out: autodoc reads any value given
# here, ``False`` included, as "on".)
autodoc_default_options = {
    "undoc-members": True,
    "show-inheritance": True,
    "member-order": "bysource",
}
autodoc_typehints = "signature"
autodoc_typehints_format = "short"
autodoc_preserve_defaults = True
autodoc_class_signature = "mixed"
autoclass_content = "class"

# napoleon: the docstrings are Google style ("Args:", "Returns:", "Example:").
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_include_init_with_doc = False
napoleon_use_rtype = False
napoleon_use_ivar = True
# One "Parameters" field per entry, its name as written: an entry naming several arguments
# ("gestation, max_branching, ...:") stays one entry instead of one ``:param:`` per name.
napoleon_use_param = False
# "Buffers:" (a module's registered buffers) reads like "Args:".
napoleon_custom_sections = [("Buffers", "params_style")]

# Cross-references to torch / tensordict / TorchRL types are not resolved (no intersphinx: the
# build stays offline), so a missing target is not an error.
nitpicky = False

html_theme = "alabaster"
html_title = "skillchain_torch API reference"
html_static_path: list[str] = []
