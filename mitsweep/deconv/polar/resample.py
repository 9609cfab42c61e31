"""Cartesian ↔ polar resampling by cubic B-splines (steps 1 and 4 of the pipeline).

:func:`to_polar` and :func:`from_polar` evaluate the splines point by point (Dr.Jit
kernels where a backend works, else ``scipy.ndimage``); :func:`angle_spectrum` and
:func:`from_angle_spectrum` are the same resamplings fused with the FFT along angle and
the angle decimation near the pole, as the deconvolution uses them;
:func:`polar_resampling` writes both as sparse matrices (exact adjoints).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import DTypeLike
import scipy.fft as sfft
import scipy.ndimage as ndi
import scipy.sparse as sp

from ..wiener import working_dtype
from . import spline
from .grid import (SPLINE_PX, PolarGrid, _channels, _fast_multiple, _pixel_levels,
                   polar_levels)
from .spline import (_angle_bspline, _spline_filter_in_place, spline_filter,
                     spline_sampling_matrix)

__all__ = ["to_polar", "from_polar", "polar_resampling", "polar_spline_coefficients",
           "angle_spectrum", "from_angle_spectrum"]

_ANGLE_PAD = (2, 3)              # periodic columns added around a polar level (taps, θ = 2π)


def _sample_on_polar(coef: np.ndarray, grid: PolarGrid,
                     levels: list[tuple[slice, int]]) -> list[np.ndarray]:
    """The spline of an image (coefficients ``coef``, mirrored beyond its ends) at the
    grid's points, level by level: for each (rows, n) of :func:`polar_levels` an array
    (rows of the run, n), angle k at 2πk/n."""
    cy, cx = grid.center
    r = grid.radii
    kernels = spline.jit_kernels()
    if kernels is None:
        out = []
        for rows, n in levels:
            th = np.arange(n) * (2 * math.pi / n)
            rr = r[rows][:, None]
            out.append(ndi.map_coordinates(coef, [cy - rr * np.sin(th), cx + rr * np.cos(th)],
                                           order=3, mode="mirror", prefilter=False,
                                           output=coef.dtype))
        return out
    # mirror the coefficients (scipy's "mirror" is NumPy's "reflect") as far as the
    # grid's taps reach, so that the kernel reads inside them
    H, W = coef.shape
    reach = float(np.abs(r).max())
    top, left = max(0, 1 - math.floor(cy - reach)), max(0, 1 - math.floor(cx - reach))
    bottom = max(0, math.floor(cy + reach) - (H - 3))
    right = max(0, math.floor(cx + reach) - (W - 3))
    padded = (np.pad(coef, ((top, bottom), (left, right)), mode="reflect")
              if top or bottom or left or right else coef)
    return [kernels.polar_samples(padded, (cy + top, cx + left), r[rows], n)
            for rows, n in levels]


def _pixels_from_polar(flat: np.ndarray, levels: list, grid: PolarGrid,
                       box: tuple[int, int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """:func:`mitsweep.jit.spline.pixels_from_polar` on ``grid``'s pole and step, or its
    reference (``scipy.ndimage``) where no Dr.Jit backend works: (values, inside) over
    the box's pixels."""
    kernels = spline.jit_kernels()
    if kernels is not None:
        return kernels.pixels_from_polar(flat, levels, center=grid.center, box=box,
                                         radial_step=grid.radial_step, r_max=grid.r_max)
    y0, y1, x0, x1 = box
    cy, cx = grid.center
    dy = cy - np.arange(y0, y1, dtype=np.float64)[:, None]
    dx = np.arange(x0, x1, dtype=np.float64)[None, :] - cx
    r = np.sqrt(dy * dy + dx * dx)
    inside = r <= grid.r_max
    th = np.arctan2(dy, dx)
    th = np.where(th < 0, th + 2 * math.pi, th)
    values = np.zeros(r.shape, dtype=flat.dtype)
    bounds = [lv[6] for lv in levels[1:]] + [math.inf]
    for (off, rows, cols, row_off, n, col_off, r_from), r_to in zip(levels, bounds):
        coef = flat[off:off + rows * cols].reshape(rows, cols)
        sel = inside & (r >= r_from) & (r < r_to)
        values[sel] = ndi.map_coordinates(
            coef, [r[sel] / grid.radial_step + row_off, th[sel] * (n / (2 * math.pi)) + col_off],
            order=3, mode="mirror", prefilter=False, output=flat.dtype)
    return values, inside


def polar_resampling(grid: PolarGrid, shape: tuple[int, int], *,
                     dtype: DTypeLike = np.float64) -> tuple[sp.csr_array, sp.csr_array]:
    """The two cubic B-spline resamplings of ``grid`` as sparse matrices.

    Parameters
    ----------
    grid : PolarGrid
        The polar grid.
    shape : (H, W)
        The Cartesian image's shape.
    dtype : float32 or float64
        Precision of the matrices' weights (default float64).

    Returns
    -------
    to_polar : (n_radii·n_angles, H·W) csr_array
        Applied to the flattened spline coefficients of an (H, W) image
        (``scipy.ndimage.spline_filter(image, order=3, mode="mirror")``), the image on
        the grid (radius-major), as :func:`to_polar`.
    from_polar : (H·W, n_radii·n_angles) csr_array
        Applied to the flattened spline coefficients of a polar image (mirror along
        radius, periodic along angle: see :func:`polar_spline_coefficients`), the
        pixels inside ``grid.r_max``; the rows of pixels beyond it are empty. This is
        :func:`from_polar` without its angular decimation near the pole.

    Their transposes are the exact adjoints. Each stores 16 entries a point: for a
    2048² image on the default grid about 1.5 GB and 0.4 GB (float32 weights, int32
    indices), which is why :func:`polar_deconvolve` evaluates the splines point by
    point instead (:mod:`mitsweep.jit.spline`).
    """
    H, W = int(shape[0]), int(shape[1])
    dt = working_dtype(np.empty(0, dtype=dtype))
    cy, cx = grid.center
    r = grid.radii[:, None]
    th = grid.angles[None, :]
    T = spline_sampling_matrix((cy - r * np.sin(th)).ravel(), (cx + r * np.cos(th)).ravel(),
                               (H, W), dtype=dt)
    yy, xx = np.mgrid[0:H, 0:W]
    rr = np.hypot(cy - yy, xx - cx).ravel()
    inside = np.flatnonzero(rr <= grid.r_max)
    ang = np.mod(np.arctan2(cy - yy, xx - cx).ravel()[inside], 2 * math.pi)
    B = spline_sampling_matrix(grid.row_of(rr[inside]), ang / grid.angle_step,
                               (grid.n_radii, grid.n_angles), periodic_cols=True,
                               dtype=dt).tocoo()
    B = sp.csr_array((B.data, (inside[B.row], B.col)), shape=(H * W, B.shape[1]))
    return T, B


def polar_spline_coefficients(polar: np.ndarray) -> np.ndarray:
    """Cubic B-spline coefficients of a polar image (n_radii, n_angles[, C]): periodic
    along angle (exact, in the Fourier domain), mirrored along radius.

    Parameters
    ----------
    polar : (n_radii, n_angles[, C]) ndarray
        The polar image, radius on axis 0; float32 stays float32.
    """
    pol, squeeze = _channels(polar)
    dt = working_dtype(pol)
    n = pol.shape[1]
    spec = sfft.rfft(pol.astype(dt, copy=False), axis=1, workers=-1)
    spec /= _angle_bspline(np.arange(spec.shape[1]), n, dt)[None, :, None]
    coef = sfft.irfft(spec, n=n, axis=1, workers=-1).astype(dt, copy=False)
    for c in range(coef.shape[2]):
        coef[..., c] = spline_filter(coef[..., c], (0,), dt)
    return coef[..., 0] if squeeze else coef


def to_polar(image: np.ndarray, grid: PolarGrid) -> np.ndarray:
    """Sample ``image`` on ``grid``: (n_radii, n_angles[, C]), radius on axis 0.

    Cubic B-spline interpolation; outside the image the image is mirrored
    (``mode="mirror"``). float32 stays float32.

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
        The Cartesian image.
    grid : PolarGrid
        The polar grid (:func:`~mitsweep.deconv.polar.grid.polar_grid` of its shape).
    """
    img, squeeze = _channels(image)
    dt = working_dtype(img)
    out = np.empty((grid.n_radii, grid.n_angles, img.shape[2]), dtype=dt)
    for c in range(img.shape[2]):
        coef = spline_filter(img[..., c], (0, 1), dt)
        (out[..., c],) = _sample_on_polar(coef, grid, polar_levels(grid, False))
    return out[..., 0] if squeeze else out


def from_polar(polar: np.ndarray, grid: PolarGrid, shape: tuple[int, int], *,
               upsample: float = 1.0, outside: np.ndarray | None = None) -> np.ndarray:
    """Map a polar image back to Cartesian pixels of ``shape`` (H, W).

    Parameters
    ----------
    polar : (n_radii, n_angles[, C]) ndarray
        The polar image, radius on axis 0.
    grid : PolarGrid
        The grid it lies on.
    shape : (H, W)
        The Cartesian image's shape.
    upsample : float
        Angle samples are first multiplied by this factor by zero-padding their FFT
        (exact for the band-limited periodic signal), which lowers the spline's error in
        angle at the rim: 1.25 adds ~1.5 dB to the round trip (measured), at 25 % more
        work; 1 (default) already gives 54-57 dB.
    outside : (H, W[, C]) ndarray, optional
        Values for pixels farther than ``grid.r_max`` from the pole (default 0).

    Returns
    -------
    (H, W[, C]) ndarray
    """
    pol, squeeze = _channels(polar)
    if pol.shape[:2] != (grid.n_radii, grid.n_angles):
        raise ValueError(f"polar image must be ({grid.n_radii}, {grid.n_angles}[, C]), "
                         f"got {polar.shape}")
    spec = sfft.rfft(pol, axis=1, workers=-1)
    out = from_angle_spectrum(spec, grid, shape, upsample=upsample, outside=outside,
                               dtype=working_dtype(pol))
    return out[..., 0] if squeeze else out


def angle_spectrum(img: np.ndarray, grid: PolarGrid, cdt: DTypeLike) -> np.ndarray:
    """rfft along angle of ``to_polar(img, grid)``, sampling inner rows at fewer angles.

    A row of radius r holds harmonics up to ``2π r · 0.75``; rows where that is below
    a quarter (a half) of ``n_angles`` are sampled at ``n_angles / 4`` (``/ 2``) angles
    and their spectra zero-padded, which is exact for such band-limited rows and saves
    about a quarter of the spline evaluations. Returns (n_radii, n_angles//2 + 1, C).

    Parameters
    ----------
    img : (H, W, C) ndarray
        The Cartesian image, channels last (one channel: C = 1).
    grid : PolarGrid
        The polar grid.
    cdt : complex64 or complex128
        The spectrum's dtype.
    """
    C = img.shape[2]
    dt = working_dtype(img)
    M = grid.n_angles // 2 + 1
    spec = np.zeros((grid.n_radii, M, C), dtype=cdt)
    levels = polar_levels(grid, True)
    for c in range(C):
        coef = spline_filter(img[..., c], (0, 1), dt)
        for (rows, n), pol in zip(levels, _sample_on_polar(coef, grid, levels)):
            f = sfft.rfft(pol, axis=1, workers=-1)
            if n == grid.n_angles:
                spec[rows, :, c] = f
            else:      # zero-padded spectrum, without the coarse level's Nyquist bin
                np.multiply(f[:, :n // 2], grid.n_angles / n, out=spec[rows, :n // 2, c])
    return spec


def from_angle_spectrum(spec: np.ndarray, grid: PolarGrid, shape: tuple[int, int], *,
                        upsample: float, outside: np.ndarray | None,
                        dtype: DTypeLike) -> np.ndarray:
    """``from_polar`` given the rfft along angle: (n_radii, n_angles//2+1, C) complex.

    Pixels are read from a spline over the angle-upsampled rows (its coefficients along
    angle computed exactly in the Fourier domain); like the sampling
    (:func:`angle_spectrum`), pixels near the centre use rows rebuilt at a quarter or
    half of the angles, keeping the harmonics a pixel image can hold there
    (2π r · 0.75 at radius r) and dropping the rest.

    Parameters
    ----------
    spec : (n_radii, n_angles // 2 + 1, C) complex ndarray
        The polar image's rfft along angle (:func:`angle_spectrum`).
    grid : PolarGrid
        The polar grid.
    shape : (H, W)
        The Cartesian image's shape.
    upsample : float
        Angle upsampling factor before the spline, as in :func:`from_polar`.
    outside : (H, W[, C]) ndarray or None
        Values of the pixels beyond ``grid.r_max`` (None: 0).
    dtype : float32 or float64
        The output's precision.

    Returns
    -------
    (H, W, C) ndarray
    """
    H, W = int(shape[0]), int(shape[1])
    C = spec.shape[2]
    n = grid.n_angles
    n2 = _fast_multiple(int(math.ceil(n * max(1.0, upsample))), 4)
    if outside is None:
        out = np.zeros((H, W, C), dtype=dtype)
    else:
        o = np.asarray(outside, dtype=dtype)
        out = (o[..., None] if o.ndim == 2 else o).copy()
        if out.shape != (H, W, C):
            raise ValueError(f"outside must be {(H, W, C)}, got {o.shape}")
    cy, cx = grid.center
    R = grid.r_max
    box = (max(0, int(math.floor(cy - R))), min(H, int(math.ceil(cy + R)) + 1),
           max(0, int(math.floor(cx - R))), min(W, int(math.ceil(cx + R)) + 1))
    if box[1] <= box[0] or box[3] <= box[2]:
        return out
    # each level's rows (a spline's reach on either side of its pixels' radii) and its
    # angles, periodically padded, one after another in one flat array
    lead, trail = _ANGLE_PAD
    levels: list[tuple[int, int, int, int, tuple]] = []
    offset = 0
    for q, nq, lo, hi in _pixel_levels(grid, n2):
        r0 = max(0, int(math.floor(grid.row_of(lo - SPLINE_PX))))
        r1 = min(grid.n_radii, int(math.ceil(grid.row_of(hi + SPLINE_PX))) + 1)
        cols = lead + nq + trail
        levels.append((q, r0, r1, nq, (offset, r1 - r0, cols, float(grid.n_inner - r0), nq,
                                       float(lead), lo if levels else min(lo, 0.0))))
        offset += (r1 - r0) * cols
    flat = np.empty(offset, dtype=dtype)
    for c in range(C):
        for q, r0, r1, nq, (off, rows, cols, *_) in levels:
            mq = min(spec.shape[1], nq // 2 + (1 if q == 1 else 0))
            scale = (nq / n) / _angle_bspline(np.arange(mq), nq, np.float64)
            s = spec[r0:r1, :mq, c] * scale.astype(dtype)[None, :]
            coef = flat[off:off + rows * cols].reshape(rows, cols)
            coef[:, lead:lead + nq] = sfft.irfft(s, n=nq, axis=1, workers=-1)
            _spline_filter_in_place(coef[:, lead:lead + nq], 0)
            coef[:, :lead] = coef[:, nq:nq + lead]                  # angles -lead..-1
            coef[:, lead + nq:] = coef[:, lead:lead + trail]        # nq..nq+trail-1
        values, inside = _pixels_from_polar(flat, [lv[-1] for lv in levels], grid, box)
        np.copyto(out[box[0]:box[1], box[2]:box[3], c], values, where=inside)
    return out
