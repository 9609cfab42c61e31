r"""Polar-domain deconvolution for rotationally symmetric setups (paper Sec. 5, Fig. 8).

For an untilted mirror the IPSF depends only on the radius of the image point and
rotates with its polar angle, so in polar coordinates (radius on axis 0, angle on
axis 1) the blur is *circulant in angle*. The pipeline:

1. Cartesian → polar (:func:`to_polar`) on a :class:`PolarGrid` with ≥ 2πR angles at a
   fast FFT length and radially oversampled rows (cubic splines; rows continue through
   the centre to negative radii, so the centre needs no special boundary);
2. FFT along the angle (exact: the angle axis is periodic, no padding needed);
3. the radius is cut into overlapping bands with hat windows that sum to one; each band
   is restored with the Wiener filter of the bank's IPSF interpolated at the band's
   radius, its transfer function evaluated analytically in (radial frequency,
   angular harmonic m), where harmonic m is tangential frequency m / (2π r) cycles/px;
4. polar → Cartesian (:func:`from_polar`) after band-limited (FFT) upsampling in angle.

The small disk around the centre, where a polar grid cannot describe a kernel, is
restored in Cartesian coordinates with the centre IPSF and blended in smoothly.

Speed: both resamplings are cubic B-spline evaluations (16 coefficients a point). Where
a Dr.Jit backend works they run as fused kernels on every core
(:mod:`mitsweep.jit.spline`) that compute each point's coordinates themselves, so
nothing is precomputed or kept between calls; elsewhere ``scipy.ndimage`` evaluates
them (one thread), the reference the kernels are tested against. Spline prefilters
along contiguous lines and the radial bands run across threads (scipy and NumPy
release the GIL); along the strided axis the prefilter runs as row-by-row recursions,
each step one NumPy operation on a whole row. A band's transfer function is an FFT of
its kernel and its Wiener filter is formed in place. The result does not depend on
the thread count. :func:`polar_resampling` gives the resamplings as sparse matrices,
whose transposes are the exact adjoints.

Modules
-------
- :mod:`.grid`: the polar grid and its angle-decimation levels;
- :mod:`.spline`: cubic B-spline prefilters, sampling matrices, the Dr.Jit dispatch;
- :mod:`.resample`: Cartesian ↔ polar (steps 1 and 4);
- :mod:`.bands`: the band plan (pure) and each band's transfer function and filter;
- :mod:`.solver`: the band-by-band solve and the Cartesian disk (steps 2-3);
- here: :func:`polar_deconvolve`, which chains them, and its memory estimate.
"""

from __future__ import annotations

import logging

import numpy as np
from numpy.typing import DTypeLike

from ...deprecation import renamed_keywords
from ...io.bank import IPSFBank
from ...resources import check_allocation
from ..kernels import check_bank_matches, radii_px, select_depth
from ..wiener import check_image_values, check_nsr, estimate_nsr, working_dtype
from . import spline
from .bands import band_length, band_plan, band_transfer
from .grid import SPLINE_PX, PolarGrid, _channels, polar_grid
from .resample import (angle_spectrum, from_angle_spectrum, from_polar, polar_resampling,
                       polar_spline_coefficients, to_polar)
from .solver import restore_bands, restore_centre
from .spline import spline_sampling_matrix

__all__ = ["PolarGrid", "polar_grid", "to_polar", "from_polar", "polar_deconvolve",
           "polar_memory_bytes", "polar_resampling", "polar_spline_coefficients",
           "spline_sampling_matrix"]

logger = logging.getLogger(__name__)


def polar_memory_bytes(grid: PolarGrid, image_shape: tuple[int, ...], dtype: DTypeLike) -> float:
    """Peak bytes of :func:`polar_deconvolve` on ``grid``.

    The angle spectrum, its filtered accumulator and the bands in flight (complex,
    half-length), the polar samples of a channel, the mirrored coefficients and the
    angle-upsampled rows and pixel values on the way back, and three copies of the
    image; nothing is kept between calls. For 2048² float32 with the benchmark's bank
    this says 446 MiB; measured (tracemalloc and Dr.Jit's allocator watermark) 257 MiB
    at the first call of a process and 191 MiB at a later one.

    Parameters
    ----------
    grid : PolarGrid
        The polar grid of the deconvolution.
    image_shape : tuple of int
        The image's (H, W[, C]).
    dtype : float32 or float64
        The working precision.
    """
    it = np.dtype(dtype).itemsize
    C = image_shape[2] if len(image_shape) == 3 else 1
    H, W = image_shape[0], image_shape[1]
    cells = float(grid.n_radii) * float(grid.n_angles)
    reach = grid.r_max + SPLINE_PX + 4
    mirrored = max(float(H) * W, 4 * reach * reach)
    return (cells * it * (2 * C + 2 + 3 * C) + mirrored * it
            + float(H) * W * it * (3 * C + 4))


@renamed_keywords(depth_mm="depth")
def polar_deconvolve(image: np.ndarray, bank: IPSFBank, *,
                     center: tuple[float, float] | None = None, nsr: float | None = None,
                     prior: str = "natural", depth: float | str | None = None,
                     r_max: float | None = None, radial_oversampling: float = 1.5,
                     angular_oversampling: float = 1.25, band_spacing: float = 0.25,
                     margin: int | None = None) -> np.ndarray:
    r"""Deconvolve a focal-sweep image of a rotationally symmetric setup in polar space.

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
        Focal-sweep image on the bank's reference pixel grid; float32 stays float32.
    bank : IPSFBank
        A ``kind="radial"`` bank (kernels for points on the +u axis).
    center : (row, col), optional
        Pole, pixels; default the optical axis (image centre).
    nsr, prior
        Wiener regulariser, see :func:`~mitsweep.deconv.wiener.wiener_deconvolve`.
        ``nsr=None`` estimates it from the image.
    depth
        Bank depth to use, mm (:func:`~mitsweep.deconv.kernels.select_depth`; default
        500 mm as in the paper). Its former name ``depth_mm`` is still accepted, with a
        :class:`DeprecationWarning`.
    r_max : float, optional
        Radius (pixels) of the region restored, default the largest bank radius plus a
        kernel size, capped at the farthest corner; pixels beyond are returned unchanged.
    radial_oversampling, angular_oversampling
        Polar sampling (:func:`polar_grid`).
    band_spacing : float
        Relative radial spacing of the band centres (0.25: a band every 25 % of radius,
        at least one kernel size apart): the IPSF and its angular scale 1/r are
        treated as constant across a band and interpolated between bands.
    margin : int, optional
        Context pixels around each band for its filter (default 1.5 K, K the kernel
        size: measured 65 dB from 3 K's result at NSR 1e-6 and 90 dB at 1e-4, with
        27 % less radial FFT work at 2048² px).

    Returns
    -------
    (H, W) or (H, W, C) ndarray

    Notes
    -----
    With polar samples :math:`y(r_j, \theta_k)` and their DFT along angle
    :math:`Y_j(m)`, band b (centre radius :math:`r_b`, window :math:`w_b(r)`) computes

    .. math:: \hat X_b(\nu, m) = \frac{H_b^*(\nu, m)}{|H_b(\nu, m)|^2 + R(\nu, m / 2\pi r_b)}
              \, \mathcal{F}_r[Y(m)](\nu),
              \qquad H_b(\nu, m) = \sum_{s, t} k_b(s, t)\, e^{-2\pi i \nu s} e^{-i m t / r_b}

    (s, t radial and tangential offsets in pixels) and the result is
    :math:`\sum_b w_b \hat x_b`, mapped back to Cartesian pixels.
    """
    img, squeeze = _channels(image)
    check_bank_matches(bank, img.shape)
    dt = working_dtype(img)
    cdt = np.complex64 if dt == np.float32 else np.complex128
    img = img.astype(dt, copy=False)
    check_image_values(img)
    kernels = select_depth(bank, depth)
    rad = radii_px(bank)
    K = kernels.shape[-1]
    if nsr is None:
        nsr = estimate_nsr(img)
        logger.info("estimated NSR %.3g", nsr)
    nsr = check_nsr(nsr)
    H, W = img.shape[:2]
    corner = polar_grid(img.shape).r_max if center is None else None
    if r_max is None:
        far = corner if corner is not None else polar_grid(img.shape, center=center).r_max
        r_max = min(float(rad.max()) + K, far)
    grid = polar_grid(img.shape, center=center, r_max=r_max,
                      radial_oversampling=radial_oversampling,
                      angular_oversampling=angular_oversampling, inner_px=SPLINE_PX,
                      outer_px=SPLINE_PX)
    check_allocation(f"polar deconvolution of {W}x{H} px on {grid.n_radii} radii x "
                     f"{grid.n_angles} angles", polar_memory_bytes(grid, img.shape, dt))
    spec = angle_spectrum(img, grid, cdt)                              # (n_r, M, C)
    plan = band_plan(grid, K, band_spacing=band_spacing, margin=margin)
    n_px = float(np.sqrt(H * W))
    acc = restore_bands(spec, plan, grid, kernels, rad, nsr=nsr, prior=prior, n_px=n_px)
    del spec
    out = from_angle_spectrum(acc, grid, (H, W), upsample=1.0, outside=img, dtype=dt)
    del acc
    restore_centre(out, img, plan, grid, kernels, rad, nsr=nsr, prior=prior, n_px=n_px)
    return out[..., 0] if squeeze else out
