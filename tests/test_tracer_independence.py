"""The tracer is an independent implementation: it must not import Mitsuba or the
renderer (docs/design.md), and optics/motion.py stays pure NumPy."""

import ast
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1] / "mitsweep"
TRACER = sorted((ROOT / "tracer").glob("*.py"))


def _imports(path):
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            mod = node.module or ""
            yield ("." * node.level) + mod


@pytest.mark.parametrize("path", TRACER, ids=lambda p: p.name)
def test_tracer_does_not_import_mitsuba_or_render(path):
    for name in _imports(path):
        assert not name.startswith("mitsuba"), f"{path.name} imports {name}"
        assert "render" not in name.split("."), f"{path.name} imports {name}"


def test_motion_module_is_pure_numpy():
    names = set(_imports(ROOT / "optics" / "motion.py"))
    assert not any(n.startswith(("drjit", "mitsuba")) for n in names)
