"""Sphinx configuration of mitsweep's documentation (built by ``bash scripts/docs.sh``)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

# autodoc imports every module, mitsweep.render and mitsweep.tracer included: they import
# Mitsuba and Dr.Jit, whose backend mitsweep.backend chooses (CUDA, else LLVM with
# libLLVM >= 19; scripts/bootstrap.sh installs it). Nothing is mocked. A documentation
# build needs no GPU, so it stays on the CPU unless the caller chose otherwise.
os.environ.setdefault("MITSWEEP_BACKEND", "llvm")

import mitsweep  # noqa: E402

project = "mitsweep"
author = "the mitsweep authors"
copyright = "the mitsweep authors, BSD-3-Clause"
release = mitsweep.__version__
version = release

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "myst_parser",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store"]
templates_path = ["_templates"]

# The API reference: one page per module, generated from the docstrings.
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"member-order": "bysource"}
autodoc_typehints = "none"          # numpydoc's Parameters sections carry the types
numpydoc_show_class_members = False  # members are listed by autodoc, once
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False

myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3

html_theme = "furo"
html_title = f"mitsweep {release}"
html_static_path: list[str] = []
