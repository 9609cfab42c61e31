"""Figures stay at the edge: no module of the compute and I/O packages imports matplotlib
or mitsweep.plots (any form of import, seen on the source by the AST checker of
test_architecture), and the tracer no longer holds figure code."""

from __future__ import annotations

from pathlib import Path

import pytest

from test_architecture import PKG, _module_name, imports_of

PACKAGES = ("optics", "tracer", "deconv", "render", "rig", "io")
FORBIDDEN = ("matplotlib", "mitsweep.plots")

def figure_imports(path: Path, package: Path = PKG) -> list[str]:
    """The imports of matplotlib or mitsweep.plots that the module at ``path`` (inside
    the ``mitsweep`` folder ``package``) makes."""
    module, is_package = _module_name(path, package.parent)
    return [f"{path.relative_to(package)}:{imp.line} {imp.how} {imp.target}"
            for imp in imports_of(path.read_text(), module, is_package)
            if imp.target and any(imp.target == f or imp.target.startswith(f + ".")
                                  for f in FORBIDDEN)]


def _modules():
    for package in PACKAGES:
        for path in sorted((PKG / package).rglob("*.py")):
            rel = path.relative_to(PKG).as_posix()
            yield pytest.param(path, id=rel)


@pytest.mark.parametrize("path", list(_modules()))
def test_compute_module_imports_no_figure_code(path):
    offences = figure_imports(path)
    assert not offences, "\n".join(offences)


def test_every_package_is_scanned():
    for package in PACKAGES:
        assert list((PKG / package).rglob("*.py")), package


@pytest.mark.parametrize("source", [
    "from ..plots import plot_bank\n",
    "from .. import plots\n",
    "def f():\n    import matplotlib.pyplot as plt\n",
    "from matplotlib.figure import Figure\n",
    "import importlib\nimportlib.import_module('matplotlib')\n",
    "import mitsweep.plots as p\n",
])
def test_the_scan_sees_planted_figure_imports(tmp_path, source):
    root = tmp_path / "tree"
    target = root / "mitsweep" / "tracer" / "_bad.py"
    target.parent.mkdir(parents=True)
    (root / "mitsweep" / "__init__.py").write_text("")
    (target.parent / "__init__.py").write_text("")
    target.write_text(source)
    assert figure_imports(target, root / "mitsweep")


def test_the_tracer_holds_no_figure_module():
    assert not (PKG / "tracer" / "figures.py").exists()
