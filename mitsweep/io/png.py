"""PNG previews of linear images (sRGB-encoded, 8 bit, written atomically)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .atomic import atomic_path

__all__ = ["linear_to_srgb", "write_png"]


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB encoding of linear values in [0, 1] (clipped).

    Parameters
    ----------
    x : ndarray
        Linear values, 1 = full white; clipped to [0, 1] and computed in float64.

    Returns
    -------
    ndarray
        sRGB-encoded values in [0, 1], float64, of ``x``'s shape.
    """
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def write_png(path: str | Path, image: np.ndarray, *, white: float | None = None,
              max_width: int | None = None) -> Path:
    """Write a linear (H, W) or (H, W, 3) image as an 8-bit sRGB PNG.

    Parameters
    ----------
    path : str or Path
        The PNG file, written atomically.
    image : (H, W), (H, W, 1), (H, W, 3) or (H, W, 4) ndarray
        Linear values; NaN is written black.
    white : float, optional
        The linear value shown as full white (default: the 99.5th percentile of the
        finite values, so that a few bright pixels do not darken the preview; a value
        <= 0 means 1).
    max_width : int, optional
        Widest image written, px: a wider one is shrunk by the smallest integer factor
        that fits (box average of the linear values, before encoding). Default: no
        limit.

    Returns
    -------
    Path
        ``path``.
    """
    from PIL import Image

    img = np.asarray(image, dtype=np.float64)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    if max_width is not None and img.shape[1] > max_width:
        k = math.ceil(img.shape[1] / max_width)
        h, w = (img.shape[0] // k) * k, (img.shape[1] // k) * k
        img = img[:h, :w].reshape(h // k, k, w // k, k, *img.shape[2:]).mean(axis=(1, 3))
    if white is None:
        finite = img[np.isfinite(img)]
        white = float(np.percentile(finite, 99.5)) if finite.size else 1.0
    white = white if white > 0 else 1.0
    srgb = (linear_to_srgb(np.nan_to_num(img / white)) * 255 + 0.5).astype(np.uint8)
    p = Path(path)
    if srgb.ndim == 3 and srgb.shape[2] not in (3, 4):
        raise ValueError(f"image must be (H, W), (H, W, 1), (H, W, 3) or (H, W, 4), "
                         f"got shape {image.shape}")
    with atomic_path(p, suffix=".png") as tmp:
        Image.fromarray(np.ascontiguousarray(srgb)).save(tmp, format="PNG")
    return p
