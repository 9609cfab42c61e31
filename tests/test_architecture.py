"""Dependency rules of DESIGN.md, checked on the source (AST), and the backend guard."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "mitsweep"

# package → modules it must never import (directly or via `from X import`).
FORBIDDEN = {
    "optics": {"mitsuba", "drjit"},
    "deconv": {"mitsuba", "drjit"},
    "io": {"mitsuba", "drjit"},
    "rig": {"mitsuba", "drjit"},
    "tracer": {"mitsuba"},
}


def _imports(path: Path):
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name.split(".")[0], node.lineno
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.module.split(".")[0], node.lineno


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_package_does_not_import_forbidden_backends(package):
    offenders = []
    for path in sorted((PKG / package).rglob("*.py")):
        for name, line in _imports(path):
            if name in FORBIDDEN[package]:
                offenders.append(f"{path.relative_to(PKG)}:{line} imports {name}")
    assert not offenders, "\n".join(offenders)


def test_only_render_imports_mitsuba():
    offenders = []
    for path in sorted(PKG.rglob("*.py")):
        rel = path.relative_to(PKG)
        if rel.parts[0] in ("render", "backend.py"):
            continue
        for name, line in _imports(path):
            if name == "mitsuba":
                offenders.append(f"{rel}:{line}")
    assert not offenders, offenders


def test_old_llvm_is_refused_before_any_kernel(tmp_path):
    """With libLLVM 15 (which aborts Dr.Jit's kernels) the guard raises a clear error."""
    candidates = sorted(Path("/usr/lib").glob("*/libLLVM-15.so*")) + \
        sorted(Path("/usr/lib").glob("*/libLLVM-1[0-8].so*"))
    if not candidates:
        pytest.skip("no libLLVM < 19 on this machine to test the guard with")
    code = ("from mitsweep.backend import select_backend, BackendError\n"
            "try:\n    select_backend()\nexcept BackendError as e:\n    print('REFUSED', e)\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env={"DRJIT_LIBLLVM_PATH": str(candidates[0]), "PATH": "/usr/bin"},
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "REFUSED" in proc.stdout and "libLLVM >= 19" in proc.stdout


def test_backend_override_is_validated(monkeypatch):
    from mitsweep import backend

    backend.select_backend.cache_clear()
    monkeypatch.setenv("MITSWEEP_BACKEND", "opencl")
    with pytest.raises(backend.BackendError, match="must be one of cuda, llvm, scalar"):
        backend.select_backend()
    backend.select_backend.cache_clear()
