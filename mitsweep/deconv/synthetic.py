"""Synthetic IPSF banks with the paper's structure, for tests and benchmarks.

The kernels mimic Fig. 4 of the paper: a cross made of a radially elongated and a
tangentially elongated Gaussian whose widths grow toward the periphery, rotated with the
polar angle. They are analytic, so the true spatially varying blur of an image can be
built exactly (:func:`synthetic_kernel_field`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..deprecation import renamed_keywords
from ..io.bank import IPSFBank
from ..optics.pixels import pixel_to_sensor

__all__ = ["synthetic_ipsf", "synthetic_radial_bank", "synthetic_grid_bank",
           "synthetic_kernel_field"]


def synthetic_ipsf(r_px: ArrayLike, theta: ArrayLike, size: int, r_max_px: float, *,
                   core: float = 0.7, radial: float = 2.5, tangential: float = 1.5) -> np.ndarray:
    """Cross-shaped unit-sum kernel(s) at radius ``r_px`` and polar angle ``theta``.

    Parameters
    ----------
    r_px, theta : float or (...) ndarray
        Image point radius (pixels) and polar angle (radians, counter-clockwise from +u).
    size : int
        Odd kernel size K.
    r_max_px : float
        Radius at which the widths reach ``core + radial`` and ``core + tangential``.

    Returns
    -------
    (..., K, K) ndarray
        Half of the energy in a Gaussian of std ``core + radial (r/r_max)²`` along the
        radial direction (``core`` across), half in one of std
        ``core + tangential (r/r_max)`` along the tangential direction.
    """
    if size % 2 == 0:
        raise ValueError(f"size must be odd, got {size}")
    r = np.asarray(r_px, dtype=np.float64)[..., None, None]
    th = np.asarray(theta, dtype=np.float64)[..., None, None]
    c = size // 2
    rows, cols = np.mgrid[0:size, 0:size].astype(np.float64)
    du, dv = cols - c, -(rows - c)
    a = np.cos(th) * du + np.sin(th) * dv      # radial component
    b = -np.sin(th) * du + np.cos(th) * dv     # tangential component
    x = np.clip(r / r_max_px, 0, None)
    s_r = core + radial * x * x
    s_t = core + tangential * x
    g1 = np.exp(-0.5 * ((a / s_r) ** 2 + (b / core) ** 2))
    g2 = np.exp(-0.5 * ((a / core) ** 2 + (b / s_t) ** 2))
    g1 /= g1.sum(axis=(-2, -1), keepdims=True)
    g2 /= g2.sum(axis=(-2, -1), keepdims=True)
    return 0.5 * (g1 + g2)


def _bank_meta(shape, **kw):
    return {"synthetic": True, "setup": {"sensor": {"resolution": [int(shape[1]), int(shape[0])]}},
            **kw}


@renamed_keywords(depths_mm="depths")
def synthetic_radial_bank(image_shape: tuple[int, int], *, n_radii: int = 19, size: int = 21,
                          r_max_px: float | None = None, extent_px: float | None = None,
                          pixel_pitch: float = 0.018, depths: ArrayLike = (500.0,),
                          **kw: float) -> IPSFBank:
    """Radial bank of :func:`synthetic_ipsf` kernels at ``n_radii`` radii from 0 to
    ``extent_px`` (default ``r_max_px``, itself default half the smaller image side).

    Parameters
    ----------
    image_shape : (H, W)
        The image the bank is for (recorded as the sensor's resolution).
    n_radii : int
        Kernels, evenly spaced in radius (default 19).
    size : int
        Odd kernel size K, px (default 21).
    r_max_px : float, optional
        Radius where the kernels reach their full width, px (default half the smaller
        image side).
    extent_px : float, optional
        Largest radius of the bank, px (default ``r_max_px``).
    pixel_pitch : float
        Pixel pitch, mm (default 0.018).
    depths : array_like
        The bank's depths, mm; every depth gets the same kernels (default one, 500 mm).
        The former keyword ``depths_mm`` is still accepted, with a
        :class:`DeprecationWarning`.
    **kw : float
        ``core``, ``radial``, ``tangential``: the kernel widths of :func:`synthetic_ipsf`,
        px.
    """
    H, W = image_shape[:2]
    r_max = float(min(H, W) / 2) if r_max_px is None else float(r_max_px)
    radii = np.linspace(0, r_max if extent_px is None else float(extent_px), n_radii)
    k = synthetic_ipsf(radii, np.zeros_like(radii), size, r_max, **kw)
    depths = np.asarray(depths, float)
    kernels = np.repeat(k[None], len(depths), axis=0).astype(np.float32)
    pts = np.stack([radii * pixel_pitch, np.zeros_like(radii)], axis=1)
    return IPSFBank(kernels=kernels, points_uv=pts, depths=depths,
                    pixel_pitch=pixel_pitch, reference_sensor_distance=30.0, kind="radial",
                    radii=radii * pixel_pitch, metadata=_bank_meta(image_shape, r_max_px=r_max))


@renamed_keywords(depths_mm="depths")
def synthetic_grid_bank(image_shape: tuple[int, int], grid_shape: tuple[int, int], *,
                        size: int = 21, r_max_px: float | None = None,
                        pixel_pitch: float = 0.018, depths: ArrayLike = (500.0,),
                        **kw: float) -> IPSFBank:
    """Grid bank of :func:`synthetic_ipsf` kernels at a (rows × cols) grid of pixels.

    Points run evenly from the first to the last pixel centre in each direction.

    Parameters
    ----------
    image_shape : (H, W)
        The image the bank is for (recorded as the sensor's resolution).
    grid_shape : (int, int)
        Grid points (rows, cols).
    size : int
        Odd kernel size K, px (default 21).
    r_max_px : float, optional
        Radius where the kernels reach their full width, px (default half the smaller
        image side).
    pixel_pitch : float
        Pixel pitch, mm (default 0.018).
    depths : array_like
        The bank's depths, mm; every depth gets the same kernels (default one, 500 mm).
        The former keyword ``depths_mm`` is still accepted, with a
        :class:`DeprecationWarning`.
    **kw : float
        ``core``, ``radial``, ``tangential``: the kernel widths of :func:`synthetic_ipsf`,
        px.
    """
    H, W = image_shape[:2]
    r_max = float(min(H, W) / 2) if r_max_px is None else float(r_max_px)
    ys = np.linspace(0, H - 1, grid_shape[0])
    xs = np.linspace(0, W - 1, grid_shape[1])
    yy, xx = np.meshgrid(ys, xs, indexing="ij")
    u, v = pixel_to_sensor(yy.ravel(), xx.ravel(), (H, W), pixel_pitch)
    k = synthetic_ipsf(np.hypot(u, v) / pixel_pitch, np.arctan2(v, u), size, r_max, **kw)
    depths = np.asarray(depths, float)
    kernels = np.repeat(k[None], len(depths), axis=0).astype(np.float32)
    pts = np.stack([u, v], axis=1)
    return IPSFBank(kernels=kernels, points_uv=pts, depths=depths,
                    pixel_pitch=pixel_pitch, reference_sensor_distance=30.0, kind="grid",
                    grid_shape=(grid_shape[0], grid_shape[1]),
                    metadata=_bank_meta(image_shape, r_max_px=r_max))


def synthetic_kernel_field(image_shape: tuple[int, int], size: int = 21,
                           r_max_px: float | None = None, **kw: float) -> np.ndarray:
    """(H, W, K, K) exact per-pixel kernels of the synthetic model (small images only).

    Parameters
    ----------
    image_shape : (H, W)
        The image's shape; the pole is the optical axis.
    size : int
        Odd kernel size K, px (default 21).
    r_max_px : float, optional
        Radius where the kernels reach their full width, px (default half the smaller
        image side).
    **kw : float
        ``core``, ``radial``, ``tangential``: the kernel widths of :func:`synthetic_ipsf`,
        px.
    """
    H, W = image_shape[:2]
    r_max = float(min(H, W) / 2) if r_max_px is None else float(r_max_px)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    u, v = pixel_to_sensor(yy, xx, (H, W), 1.0)   # in pixels: a pitch of one
    return synthetic_ipsf(np.hypot(u, v), np.arctan2(v, u), size, r_max, **kw)
