"""The one place that chooses the Dr.Jit / Mitsuba backend, before any kernel runs.

Dr.Jit's LLVM (CPU) backend aborts the whole process on libLLVM < 19 ("LLVM ERROR:
Cannot select … fminimum"). :func:`select_backend` inspects the library without
compiling anything and picks, in order: CUDA when a GPU is usable, LLVM when
libLLVM >= 19 is loaded, otherwise it raises :class:`BackendError` with a one-line
instruction. ``MITSWEEP_BACKEND=cuda|llvm|scalar`` forces a choice; ``scalar`` is the
documented slow fallback for Mitsuba only (Python sensors run ~40× slower there, and the
tracer refuses it).
"""

from __future__ import annotations

import functools
import logging
import os

__all__ = ["BackendError", "MIN_LLVM", "llvm_version", "select_backend", "mitsuba_variant",
           "set_mitsuba_variant", "drjit_module"]

logger = logging.getLogger(__name__)

MIN_LLVM = (19, 0, 0)
_BACKENDS = ("cuda", "llvm", "scalar")


class BackendError(RuntimeError):
    """No usable Dr.Jit backend (the message says what to install or set)."""


def llvm_version() -> tuple[int, int, int] | None:
    """Version of the libLLVM Dr.Jit loaded, or None if none was found (no kernel runs)."""
    import drjit as dr

    if not dr.has_backend(dr.JitBackend.LLVM):
        return None
    return tuple(dr.detail.llvm_version())


def _cuda_usable() -> bool:
    import drjit as dr

    try:
        return bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:  # pragma: no cover - driver problems
        return False


@functools.lru_cache(maxsize=None)
def select_backend(prefer: str | None = None) -> str:
    """``"cuda"``, ``"llvm"`` or ``"scalar"``; checked before any kernel is compiled.

    Parameters
    ----------
    prefer : str, optional
        Force a backend (default: ``$MITSWEEP_BACKEND`` or automatic).

    Raises
    ------
    BackendError
        If the requested or any backend is unusable, e.g. libLLVM < 19.
    """
    choice = prefer or os.environ.get("MITSWEEP_BACKEND") or None
    if choice is not None and choice not in _BACKENDS:
        raise BackendError(f"MITSWEEP_BACKEND: must be one of {', '.join(_BACKENDS)}, "
                           f"got {choice!r}")
    if choice in (None, "cuda") and _cuda_usable():
        return "cuda"
    if choice == "cuda":
        raise BackendError("backend 'cuda' requested but no CUDA device is usable")
    if choice == "scalar":
        return "scalar"
    version = llvm_version()
    if version is None:
        raise BackendError("Dr.Jit found no libLLVM: install libLLVM >= 19 "
                           "(Debian/Ubuntu: apt-get install libllvm19) or set "
                           "DRJIT_LIBLLVM_PATH to it")
    if version < MIN_LLVM:
        raise BackendError(f"Dr.Jit loaded libLLVM {'.'.join(map(str, version))}, which aborts "
                           f"on its kernels; install libLLVM >= 19 (apt-get install libllvm19) "
                           f"or point DRJIT_LIBLLVM_PATH at it")
    return "llvm"


def mitsuba_variant(spectrum: str = "rgb", prefer: str | None = None) -> str:
    """The Mitsuba variant for the selected backend, e.g. ``llvm_ad_rgb``."""
    backend = select_backend(prefer)
    return f"scalar_{spectrum}" if backend == "scalar" else f"{backend}_ad_{spectrum}"


def set_mitsuba_variant(spectrum: str = "rgb", prefer: str | None = None) -> str:
    """Select the Mitsuba variant (idempotent) and return its name."""
    import mitsuba as mi

    variant = mitsuba_variant(spectrum, prefer)
    if mi.variant() != variant:
        mi.set_variant(variant)
        logger.info("mitsuba variant %s", variant)
    return variant


def drjit_module(prefer: str | None = None):
    """``drjit.cuda`` or ``drjit.llvm`` for the tracer (scalar is refused: too slow)."""
    backend = select_backend(prefer)
    if backend == "scalar":
        raise BackendError("the tracer needs the 'llvm' or 'cuda' backend, not 'scalar'")
    import importlib

    return importlib.import_module(f"drjit.{backend}")
