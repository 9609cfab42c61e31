"""Image quality inside the mirror's image: PSNR and SSIM, per radius, per depth band.

SSIM uses Wang et al. (2004)'s settings [1]_ through :func:`skimage.metrics.structural_similarity`
(Gaussian weights σ = 1.5, K1 = 0.01, K2 = 0.03, population covariance), whose full SSIM
map is then averaged over the mask, so that pixels outside the mirror's image never count.

References
----------
.. [1] Z. Wang, A. C. Bovik, H. R. Sheikh and E. P. Simoncelli, "Image quality
   assessment: from error visibility to structural similarity", IEEE Trans. Image
   Process. 13(4), 600–612, 2004.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from ..deprecation import renamed_keywords
from ..optics.pixels import optical_center_px

__all__ = ["psnr", "ssim_map", "ssim", "disk_mask", "radial_bins", "per_radius",
           "per_depth_band", "WANG_SSIM"]

#: Wang et al. 2004 settings, as keyword arguments of skimage's structural_similarity.
WANG_SSIM = dict(gaussian_weights=True, sigma=1.5, K1=0.01, K2=0.03,
                 use_sample_covariance=False)


def _pair(image, reference, mask):
    a = np.asarray(image, dtype=np.float64)
    b = np.asarray(reference, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"image {a.shape} and reference {b.shape} differ in shape")
    if a.ndim not in (2, 3):
        raise ValueError(f"images must be (H, W) or (H, W, C), got {a.shape}")
    if mask is None:
        m = np.ones(a.shape[:2], dtype=bool)
    else:
        m = np.asarray(mask, dtype=bool)
        if m.shape != a.shape[:2]:
            raise ValueError(f"mask must be {a.shape[:2]}, got {m.shape}")
    return a, b, m


def psnr(image: np.ndarray, reference: np.ndarray, *, mask: np.ndarray | None = None,
         data_range: float = 1.0) -> float:
    """Peak signal-to-noise ratio, dB: ``10 log10(data_range² / MSE)`` over ``mask``.

    All channels of masked pixels count. Returns ``inf`` for identical images and
    ``nan`` for an empty mask.

    Parameters
    ----------
    image : (H, W) or (H, W, C) array_like
        The image to score.
    reference : array_like
        The reference (ground truth), the shape of ``image``.
    mask : (H, W) bool ndarray, optional
        Pixels that count (default all).
    data_range : float
        The peak value: the images' range (default 1.0, relative exposure).
    """
    a, b, m = _pair(image, reference, mask)
    if not m.any():
        return math.nan
    mse = float(np.mean((a[m] - b[m]) ** 2))
    return math.inf if mse == 0 else 10.0 * math.log10(data_range ** 2 / mse)


def ssim_map(image: np.ndarray, reference: np.ndarray, *, data_range: float = 1.0) -> np.ndarray:
    """Per-pixel SSIM map (H, W) with Wang et al.'s settings (channels averaged).

    Parameters
    ----------
    image : (H, W) or (H, W, C) array_like
        The image to score.
    reference : array_like
        The reference (ground truth), the shape of ``image``.
    data_range : float
        The images' range (default 1.0, relative exposure).
    """
    from skimage.metrics import structural_similarity

    a, b, _ = _pair(image, reference, None)
    kw = dict(WANG_SSIM, data_range=data_range, full=True)
    if a.ndim == 3:
        maps = [structural_similarity(a[..., c], b[..., c], **kw)[1] for c in range(a.shape[2])]
        return np.mean(maps, axis=0)
    return structural_similarity(a, b, **kw)[1]


def _masked_mean(values: np.ndarray, mask: np.ndarray) -> float:
    return float(values[mask].mean()) if mask.any() else math.nan


def ssim(image: np.ndarray, reference: np.ndarray, *, mask: np.ndarray | None = None,
         data_range: float = 1.0) -> float:
    """Mean SSIM over ``mask`` (Wang et al. 2004 settings); nan for an empty mask.

    Parameters
    ----------
    image : (H, W) or (H, W, C) array_like
        The image to score.
    reference : array_like
        The reference (ground truth), the shape of ``image``.
    mask : (H, W) bool ndarray, optional
        Pixels whose SSIM is averaged (default all); the SSIM map itself is computed on
        the whole image.
    data_range : float
        The images' range (default 1.0, relative exposure).
    """
    a, b, m = _pair(image, reference, mask)
    return _masked_mean(ssim_map(a, b, data_range=data_range), m)


def disk_mask(shape: tuple[int, ...], radius_px: float, *,
              center: tuple[float, float] | None = None) -> np.ndarray:
    """(H, W) bool: pixels whose centre lies within ``radius_px`` of ``center``.

    Parameters
    ----------
    shape : tuple of int
        The image's shape, (H, W[, C]).
    radius_px : float
        The disk's radius, px.
    center : (float, float), optional
        The disk's centre (row, col), px (default the optical axis,
        :func:`~mitsweep.optics.pixels.optical_center_px`).
    """
    cy, cx = optical_center_px(shape) if center is None else center
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]]
    return np.hypot(yy - cy, xx - cx) <= radius_px


def radial_bins(shape: tuple[int, ...], edges_px: ArrayLike, *,
                center: tuple[float, float] | None = None) -> np.ndarray:
    """(H, W) int: radial bin ``[edges[i], edges[i+1])`` of each pixel; −1 outside.

    Parameters
    ----------
    shape : tuple of int
        The image's shape, (H, W[, C]).
    edges_px : sequence of float
        At least two increasing bin edges, px from ``center``.
    center : (float, float), optional
        The centre (row, col), px (default the optical axis).
    """
    edges = np.asarray(edges_px, dtype=np.float64)
    if edges.ndim != 1 or len(edges) < 2 or np.any(np.diff(edges) <= 0):
        raise ValueError("edges_px must be at least two increasing radii")
    cy, cx = optical_center_px(shape) if center is None else center
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]]
    r = np.hypot(yy - cy, xx - cx)
    idx = np.searchsorted(edges, r, side="right") - 1
    idx[(r < edges[0]) | (r >= edges[-1])] = -1
    return idx


def _per_label(image, reference, labels, n, mask, data_range):
    a, b, m = _pair(image, reference, mask)
    smap = ssim_map(a, b, data_range=data_range)
    out_p, out_s, count = [], [], []
    for i in range(n):
        sel = (labels == i) & m
        out_p.append(psnr(a, b, mask=sel, data_range=data_range))
        out_s.append(_masked_mean(smap, sel))
        count.append(int(sel.sum()))
    return {"psnr": np.asarray(out_p), "ssim": np.asarray(out_s), "pixels": np.asarray(count)}


def per_radius(image: np.ndarray, reference: np.ndarray, edges_px: ArrayLike, *,
               center: tuple[float, float] | None = None, mask: np.ndarray | None = None,
               data_range: float = 1.0) -> dict:
    """PSNR and SSIM in radial bins around ``center`` (default the optical axis).

    Parameters
    ----------
    image : (H, W) or (H, W, C) array_like
        The image to score.
    reference : array_like
        The reference (ground truth), the shape of ``image``.
    edges_px : sequence of float
        At least two increasing bin edges, px from ``center``.
    center : (float, float), optional
        The centre (row, col), px (default the optical axis).
    mask : (H, W) bool ndarray, optional
        Pixels that count (default all).
    data_range : float
        The images' range (default 1.0, relative exposure).

    Returns
    -------
    dict
        ``radius_px`` (bin centres), ``edges_px``, ``psnr`` (dB), ``ssim``, ``pixels``
        (count per bin), each an array of length ``len(edges_px) - 1``; empty bins hold
        nan. SSIM uses the whole image's SSIM map, averaged per bin.
    """
    edges = np.asarray(edges_px, dtype=np.float64)
    labels = radial_bins(np.shape(image), edges, center=center)
    res = _per_label(image, reference, labels, len(edges) - 1, mask, data_range)
    return {"radius_px": 0.5 * (edges[:-1] + edges[1:]), "edges_px": edges, **res}


@renamed_keywords(edges_mm="edges")
def per_depth_band(image: np.ndarray, reference: np.ndarray, depth: np.ndarray,
                   edges: ArrayLike, *, mask: np.ndarray | None = None, data_range: float = 1.0
                  ) -> dict:
    """PSNR and SSIM per depth band ``[edges[i], edges[i+1])`` of a depth AOV map.

    Parameters
    ----------
    image : (H, W) or (H, W, C) array_like
        The image to score.
    reference : array_like
        The reference (ground truth), the shape of ``image``.
    depth : (H, W) ndarray
        Depth of each pixel, mm (e.g. the renderer's depth AOV); non-finite pixels
        (no hit) are in no band.
    edges : sequence of float
        Increasing band edges, mm (the last may be ``inf``). The former keyword
        ``edges_mm`` is still accepted, with a :class:`DeprecationWarning`.
    mask : (H, W) bool ndarray, optional
        Pixels that count (default all).
    data_range : float
        The images' range (default 1.0, relative exposure).

    Returns
    -------
    dict with ``edges_mm`` (the edges, under their former key), ``psnr``, ``ssim``,
    ``pixels`` (arrays of length n_bands).
    """
    d = np.asarray(depth, dtype=np.float64)
    if d.shape != np.shape(image)[:2]:
        raise ValueError(f"depth map must be {np.shape(image)[:2]}, got {d.shape}")
    band_edges = np.asarray(edges, dtype=np.float64)
    if band_edges.ndim != 1 or len(band_edges) < 2 or np.any(~(np.diff(band_edges) > 0)):
        raise ValueError("edges must be at least two increasing depths")
    finite = np.isfinite(d)
    labels = np.full(d.shape, -1)
    idx = np.searchsorted(band_edges, np.where(finite, d, -np.inf), side="right") - 1
    ok = finite & (d >= band_edges[0]) & (d < band_edges[-1])
    labels[ok] = idx[ok]
    res = _per_label(image, reference, labels, len(band_edges) - 1, mask, data_range)
    return {"edges_mm": band_edges, **res}
