"""``mitsweep.rig`` depends only on optics, config and the small io helpers (docs/design.md):
never on the renderer, the tracer, Mitsuba or Dr.Jit."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

RIG = Path(__file__).resolve().parents[1] / "mitsweep" / "rig"
ALLOWED_PACKAGE_MODULES = {"optics", "config", "io", "deprecation"}   # io: atomic writes of the record; deprecation: renamed names
FORBIDDEN = {"mitsuba", "drjit", "matplotlib", "mitsweep.render", "mitsweep.tracer",
             "mitsweep.deconv"}


@pytest.mark.parametrize("path", sorted(RIG.glob("*.py")), ids=lambda p: p.name)
def test_rig_module_imports_stay_inside_its_layer(path):
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level >= 2:   # from ..X import: a sibling package of rig
                top = (node.module or "").split(".")[0]
                names = [a.name for a in node.names]
                assert top in ALLOWED_PACKAGE_MODULES or (top == "" and names == ["__version__"]), \
                    f"{path.name}: from {'.' * node.level}{node.module} import {names}"
            elif node.level == 0 and node.module:
                assert not any(node.module == f or node.module.startswith(f + ".")
                               for f in FORBIDDEN), f"{path.name}: from {node.module}"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                assert not any(alias.name == f or alias.name.startswith(f + ".")
                               for f in FORBIDDEN), f"{path.name}: import {alias.name}"
