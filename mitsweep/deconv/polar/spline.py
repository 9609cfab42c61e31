"""Cubic B-spline evaluation for the polar resamplings: prefilters, sampling matrices,
and the choice between the Dr.Jit kernels and ``scipy.ndimage``.

:func:`jit_kernels` and :func:`threads` are looked up through this module at every call,
so that a test can replace them (``monkeypatch.setattr(spline, "jit_kernels", ...)``).
"""

from __future__ import annotations

import math
import os
import sys
from concurrent.futures import ThreadPoolExecutor
from types import ModuleType

import numpy as np
from numpy.typing import DTypeLike
import scipy.ndimage as ndi
import scipy.sparse as sp

__all__ = ["spline_sampling_matrix", "jit_kernels", "threads"]

# -- cubic B-spline resampling ---------------------------------------------------------
#
# Both directions of the polar resampling evaluate a cubic B-spline (16 coefficients a
# point). Where a Dr.Jit backend works they run as fused kernels on every core
# (:mod:`mitsweep.jit.spline`), the points' coordinates computed in the kernel, so
# nothing is built, cached or paged in between calls; elsewhere as
# ``scipy.ndimage.map_coordinates`` (one thread), which is also the reference the
# kernels are tested against. :func:`spline_sampling_matrix` writes the same
# evaluation as a sparse matrix, for the explicit operators of :func:`polar_resampling`.

_TAPS = 16                       # a cubic B-spline in 2-D reads 4 x 4 coefficients
_BUILD_CHUNK = 1 << 13           # points per chunk while a matrix is built (cache-sized)


def _mirror_index(i: np.ndarray, n: int) -> np.ndarray:
    """Index ``i`` on an axis of length ``n`` under scipy.ndimage's ``"mirror"``
    extension (reflection about the end samples: … 2 1 | 0 1 … n-1 | n-2 …)."""
    if n == 1:
        return np.zeros_like(i)
    if i.size and i.min() >= 0 and i.max() < n:
        return i
    period = 2 * n - 2
    i = np.mod(i, period)
    return np.where(i >= n, period - i, i)


def _bspline_taps(x: np.ndarray, dtype) -> tuple[np.ndarray, np.ndarray]:
    """First tap index (int64, from float64 ``x``) and the four cubic B-spline weights
    (4, n), computed in ``dtype``."""
    f = np.floor(x)
    t = (x - f).astype(dtype, copy=False)
    s = 1 - t
    w = np.empty((4,) + x.shape, dtype=dtype)
    np.multiply(s * s, s * dtype.type(1 / 6), out=w[0])
    t2 = t * t
    np.multiply(t2, t * dtype.type(1 / 6), out=w[3])
    np.subtract(dtype.type(2 / 3) + 0.5 * t2 * t, t2, out=w[1])      # (3t³ - 6t² + 4) / 6
    np.subtract(1 - w[0] - w[3], w[1], out=w[2])
    return f.astype(np.int64) - 1, w


def spline_sampling_matrix(rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int], *,
                           periodic_cols: bool = False, dtype: DTypeLike = np.float64
                          ) -> sp.csr_array:
    r"""(n_points, H·W) sparse matrix that evaluates a cubic B-spline at (rows, cols).

    Applied to the flattened (C order) B-spline coefficients of an (H, W) array
    (``scipy.ndimage.spline_filter(a, order=3, mode="mirror")``) it gives what
    ``scipy.ndimage.map_coordinates(coef, [rows, cols], order=3, mode="mirror",
    prefilter=False)`` gives, to round-off. Beyond the ends the coefficients are
    mirrored; with ``periodic_cols`` the columns wrap instead (the angle of a polar
    image). Its transpose is the exact adjoint.

    Parameters
    ----------
    rows, cols : (n_points,) array_like
        Fractional pixel coordinates (pixel centres at integers).
    shape : (H, W)
    dtype
        Of the weights (float32 for float32 images).

    Notes
    -----
    Point p at :math:`(y, x)` reads :math:`\sum_{a,b=0}^{3} \beta_a(y)\,\beta_b(x)\,
    c[\lfloor y\rfloor - 1 + a, \lfloor x\rfloor - 1 + b]` with the cubic B-spline
    weights of the fractional parts; 16 stored entries a point (repeated indices at a
    mirrored edge add up).
    """
    r = np.asarray(rows, dtype=np.float64).ravel()
    c = np.asarray(cols, dtype=np.float64).ravel()
    dtype = np.dtype(dtype)
    if r.shape != c.shape:
        raise ValueError(f"rows and cols must have the same size, got {r.size} and {c.size}")
    H, W = int(shape[0]), int(shape[1])
    n = r.size
    it = np.int32 if max(H * W, _TAPS * n + 1) < 2 ** 31 else np.int64
    data = np.empty((n, _TAPS), dtype=dtype)
    indices = np.empty((n, _TAPS), dtype=it)
    taps = np.arange(4)[:, None]
    pairs = indices.view(np.int64) if it == np.int32 and sys.byteorder == "little" else None
    # entries are point-major but computed tap by tap (NumPy's loops over a last axis
    # of 4 are several times slower): each weight column a strided write, and int32
    # index pairs (taps b = 0, 1 and 2, 3 of a row) one int64 sum each
    for s in range(0, n, _BUILD_CHUNK):
        e = min(n, s + _BUILD_CHUNK)
        ri, wr = _bspline_taps(r[s:e], dtype)
        ci, wc = _bspline_taps(c[s:e], dtype)
        ri = _mirror_index(ri[None, :] + taps, H) * W                          # (4, m)
        ci = ci[None, :] + taps
        ci = np.mod(ci, W) if periodic_cols else _mirror_index(ci, W)
        for a in range(4):
            for b in range(4):
                np.multiply(wr[a], wc[b], out=data[s:e, 4 * a + b])
        if pairs is not None:
            c01, c23 = ci[0] | (ci[1] << 32), ci[2] | (ci[3] << 32)
            for a in range(4):
                ra = ri[a] * ((1 << 32) + 1)
                np.add(ra, c01, out=pairs[s:e, 2 * a])
                np.add(ra, c23, out=pairs[s:e, 2 * a + 1])
        else:
            indices[s:e] = (ri[:, None, :] + ci[None, :, :]).reshape(_TAPS, e - s).T
    indptr = np.arange(0, _TAPS * n + 1, _TAPS, dtype=it)
    return sp.csr_array((data.reshape(-1), indices.reshape(-1), indptr), shape=(n, H * W))


def threads() -> int:
    """Cores this process may run on (the band and prefilter threads)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def jit_kernels() -> ModuleType | None:
    """:mod:`mitsweep.jit.spline` where a Dr.Jit backend works, else None (then
    ``scipy.ndimage`` evaluates the splines)."""
    from ... import jit

    if jit.available() is None:
        return None
    from ...jit import spline

    return spline


_POLE = math.sqrt(3) - 2          # the cubic B-spline prefilter's pole
_POLE_HORIZON = int(math.ceil(math.log(1e-15) / math.log(-_POLE)))   # |z|^k < 1e-15


def _spline_filter_rows(c: np.ndarray) -> None:
    """Cubic B-spline prefilter along axis 0 of the 2-D array ``c``, in place (mirror
    ends, as ``scipy.ndimage.spline_filter1d(..., axis=0, mode="mirror")``): the causal
    and anticausal recursions of Unser's filter run row by row, each step one NumPy
    operation on a whole contiguous row, which is 4-5x faster than ndimage's line
    copies along a strided axis (measured, 2048² float32)."""
    n = c.shape[0]
    z = c.dtype.type(_POLE)
    # causal: c+[0] = sum_k z^k x[k] (the mirror image's terms lie beyond the horizon)
    first = c[0].copy()
    for k in range(1, _POLE_HORIZON):
        first += c.dtype.type(_POLE ** k) * c[k]
    c[0] = first
    for i in range(1, n):
        c[i] += z * c[i - 1]
    # anticausal: c-[n-1] = z / (z² - 1) (c+[n-1] + z c+[n-2]), c-[i] = z (c-[i+1] - c+[i])
    c[n - 1] = c.dtype.type(_POLE / (_POLE * _POLE - 1)) * (c[n - 1] + z * c[n - 2])
    for i in range(n - 2, -1, -1):
        np.subtract(c[i + 1], c[i], out=c[i])
        c[i] *= z
    c *= c.dtype.type(6)                  # the filter's gain (1 - z)(1 - 1/z)


def spline_filter(a: np.ndarray, axes: tuple[int, ...], dtype: DTypeLike) -> np.ndarray:
    """Cubic B-spline coefficients of the 2-D array ``a`` along ``axes`` (mirror ends),
    as ``scipy.ndimage.spline_filter1d`` gives them: along axis 0 row by row
    (:func:`_spline_filter_rows`), along axis 1 with ndimage in blocks across threads
    (it releases the GIL): each line is filtered whole, so the result is the same.

    Parameters
    ----------
    a : (M, N) array_like
        The samples; not modified.
    axes : tuple of int
        The axes filtered, in order: ``(0,)``, ``(1,)`` or ``(0, 1)``.
    dtype : dtype
        The coefficients' type, and the precision of the recursions (float32 or
        float64).

    Returns
    -------
    (M, N) ndarray of ``dtype``
        The coefficients: a new array.
    """
    out = np.array(a, dtype=dtype, copy=True)
    _spline_filter_in_place(out, axes)
    return out


def _spline_filter_in_place(out: np.ndarray, axes: int | tuple[int, ...]) -> None:
    """:func:`spline_filter` written over the 2-D array (or view) ``out``."""
    dtype = out.dtype
    for axis in (axes,) if isinstance(axes, int) else axes:
        if axis == 0 and out.shape[0] > 2 * _POLE_HORIZON:
            _spline_filter_rows(out)
            continue
        n_other = out.shape[1 - axis]
        edges = np.linspace(0, n_other, min(threads(), max(1, n_other // 64)) + 1).astype(int)

        def run(k, axis=axis, edges=edges):
            sl = [slice(None), slice(None)]
            sl[1 - axis] = slice(edges[k], edges[k + 1])
            out[tuple(sl)] = ndi.spline_filter1d(out[tuple(sl)], order=3, axis=axis,
                                                 output=dtype, mode="mirror")

        with ThreadPoolExecutor(len(edges) - 1) as pool:
            list(pool.map(run, range(len(edges) - 1)))


def _angle_bspline(m: np.ndarray, n: int, dtype) -> np.ndarray:
    """DFT of the periodic cubic B-spline's samples (1/6, 4/6, 1/6) at harmonics m of
    n: dividing a periodic signal's spectrum by it gives its spline coefficients."""
    return ((4 + 2 * np.cos(2 * math.pi * np.asarray(m) / n)) / 6).astype(dtype)
