"""Sphinx configuration of mitsweep's documentation (built by ``bash scripts/docs.sh``)."""

from __future__ import annotations

import importlib
import inspect
import os
import pkgutil
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent / "_ext"))

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
    "mathml",          # docs/_ext/mathml.py: math as MathML at build time (no CDN, no script)
    "sphinx.ext.viewcode",
    "numpydoc",
    "myst_parser",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store"]
# The API reference: one page per package and module (written into api/generated/ by
# _write_api_pages below, before each build), documented by autodoc from the docstrings.
autodoc_default_options = {"member-order": "bysource"}
# Signatures show their types (every public callable is annotated); the Parameters
# sections keep the prose. Types print short (``Setup``, not ``mitsweep.config.Setup``) and
# link to their pages; names that two modules define (``Placement``: the TOML record in
# mitsweep.config, the rigid transform in mitsweep.optics.placement) are linked by their
# full name, resolved in _resolve_reexport below.
autodoc_typehints = "signature"
autodoc_typehints_format = "short"
python_maximum_signature_line_length = 88   # one parameter per line beyond this
# A name a package re-exports in its __all__ is documented on that package's page too;
# viewcode's source pages link back only to where a name is defined (following the
# import would write anchors the re-exporting page does not have).
viewcode_follow_imported_members = False
numpydoc_show_class_members = False  # members are listed by autodoc, once
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False

myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3

html_theme = "furo"
html_title = f"mitsweep {release}"
html_static_path = ["_static"]
html_css_files = ["mitsweep.css"]    # code and signatures wrap instead of being cut off
html_math_renderer = "mathml"


# -- the API reference ------------------------------------------------------------------
# Written here rather than by autosummary: a package that re-exports a function named like
# its module (mitsweep.optics.chief_ray, mitsweep.rig.capture, mitsweep.render.user_scene)
# would get the function's page in place of the module's.

#: The public packages and modules (their submodules are found by walking them).
API_ROOTS = ["mitsweep.config", "mitsweep.optics", "mitsweep.photo", "mitsweep.tracer",
             "mitsweep.render", "mitsweep.deconv", "mitsweep.design", "mitsweep.pipeline",
             "mitsweep.datasets",
             "mitsweep.rig", "mitsweep.io", "mitsweep.backend", "mitsweep.jit", "mitsweep.resources",
             "mitsweep.plots"]
_ABBREVIATIONS = ("Eq.", "Eqs.", "Fig.", "Figs.", "Sec.", "e.g.", "i.e.", "et al.", "vs.")


def _summary(module) -> str:
    """The first sentence of a module's docstring (its first paragraph if a sentence
    cut there would break inline markup)."""
    doc = inspect.getdoc(module) or ""
    para = " ".join(doc.split("\n\n", 1)[0].split())
    for m in re.finditer(r"\.(\s|$)", para):
        head = para[:m.start() + 1]
        if head.endswith(_ABBREVIATIONS) or head.count("``") % 2 or head.count("`") % 2:
            continue
        return head
    return para


def _title(name: str) -> list[str]:
    text = name.replace("_", "\\_")
    return [text, "=" * len(text), ""]


def _module_page(name: str, pages: dict[str, str]) -> None:
    module = importlib.import_module(name)
    lines = _title(name)
    if hasattr(module, "__path__"):  # a package: its overview, its names, its modules
        lines += [f".. automodule:: {name}", ""]
        exported = []
        for attr in getattr(module, "__all__", []):
            obj = getattr(module, attr, None)
            home = getattr(obj, "__module__", None)
            if home and home != name and home.startswith("mitsweep") and hasattr(obj, "__qualname__"):
                exported.append(f"- :py:obj:`{attr} <{home}.{obj.__qualname__}>`")
        if exported:
            lines += ["Names", "-----", "", f"Exported by ``{name}``, documented where they are "
                      "defined:", "", *exported, ""]
        subs = sorted(info.name for info in pkgutil.iter_modules(module.__path__)
                      if not info.name.startswith("_"))
        if subs:
            lines += ["Modules", "-------", ""]
            for sub in subs:
                full = f"{name}.{sub}"
                lines.append(f"- :py:mod:`{full}`: {_summary(importlib.import_module(full))}")
                _module_page(full, pages)
            lines += ["", ".. toctree::", "   :hidden:", "", *(f"   {name}.{s}" for s in subs), ""]
    else:
        lines += [f".. automodule:: {name}", "   :members:", "   :show-inheritance:", ""]
    pages[name] = "\n".join(lines)


def _write_api_pages(app) -> None:
    out = Path(app.srcdir) / "api" / "generated"
    out.mkdir(parents=True, exist_ok=True)
    pages: dict[str, str] = {}
    for name in API_ROOTS:
        _module_page(name, pages)
    for name, text in pages.items():
        path = out / f"{name}.rst"
        if not path.is_file() or path.read_text() != text:  # unchanged pages stay unchanged
            path.write_text(text)
    for path in out.glob("*.rst"):
        if path.stem not in pages:
            path.unlink()


def _resolve_reexport(app, env, node, contnode):
    """A reference to a name through the package that re-exports it
    (``mitsweep.tracer.integrated_psf``) resolves to where it is documented
    (``mitsweep.tracer.ipsf.integrated_psf``)."""
    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "")
    modname, _, attr = target.rpartition(".")
    if not modname.startswith("mitsweep"):
        return None
    try:
        obj = getattr(importlib.import_module(modname), attr)
    except (ImportError, AttributeError):
        return None
    home, qualname = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    if not home or not qualname or f"{home}.{qualname}" == target:
        return None
    return env.get_domain("py").resolve_xref(env, node["refdoc"], app.builder, node["reftype"],
                                             f"{home}.{qualname}", node, contnode)


def _skip_deprecated(app, what, name, obj, skip, options):
    """Deprecated aliases (``SweepRange.focus_min_mm`` and the like) stay out of the
    listings: their docstrings start with "Deprecated alias"; the class's docstring says
    they still read."""
    doc = getattr(obj, "__doc__", None) or ""
    if doc.lstrip().lower().startswith("deprecated alias"):
        return True
    return None


def setup(app):
    app.connect("builder-inited", _write_api_pages)
    app.connect("autodoc-skip-member", _skip_deprecated)
    app.connect("missing-reference", _resolve_reexport)
