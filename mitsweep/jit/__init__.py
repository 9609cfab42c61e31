"""Dr.Jit versions of numeric kernels that other units call with NumPy arrays.

:mod:`mitsweep.deconv` is NumPy/SciPy and must work where no Dr.Jit backend does; where
one does, its hot loops run here instead, on every core (or the GPU): NumPy arrays in,
NumPy arrays out, Dr.Jit types never leave this unit. Each kernel has a NumPy/SciPy
reference in the unit that calls it, which is also its fallback (:func:`available`
says which one runs) and what the tests compare it with.

- :mod:`mitsweep.jit.spline`: cubic B-spline evaluation on polar and Cartesian grids
  (the polar deconvolution's resamplings), the sample coordinates computed in the
  kernel, so nothing is precomputed or stored between calls.
"""

from __future__ import annotations

import functools
import logging

__all__ = ["available"]

logger = logging.getLogger(__name__)


@functools.cache
def available() -> str | None:
    """The Dr.Jit backend these kernels run on (``"llvm"`` or ``"cuda"``, as
    :func:`mitsweep.backend.select_backend` chooses), or None where there is none
    (no usable libLLVM, or ``MITSWEEP_BACKEND=scalar``): callers then use their
    NumPy/SciPy reference."""
    from ..backend import BackendError, select_backend

    try:
        backend = select_backend()
    except (BackendError, ImportError) as exc:
        logger.info("no Dr.Jit backend for the numeric kernels (%s): NumPy/SciPy instead", exc)
        return None
    return backend if backend in ("llvm", "cuda") else None
