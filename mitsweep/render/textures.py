"""Offline textures with high-frequency content (no download).

Procedural resolution targets (Siemens star, bar chart, checkerboard) and the images
bundled with scikit-image. Everything is returned as linear-light float32 RGB arrays
(H, W, 3) in [0, 1], ready for a Mitsuba ``bitmap`` texture.
"""

from __future__ import annotations

import functools

import numpy as np

from ..deprecation import renamed_keywords
from ..io.camera import srgb_to_linear

__all__ = ["siemens_star", "bar_chart", "checkerboard", "skimage_texture", "texture",
           "TEXTURE_NAMES", "srgb_to_linear"]

#: Images shipped with scikit-image (no network) used as textures.
_SKIMAGE = ("astronaut", "camera", "coffee", "chelsea", "brick", "grass", "gravel", "text",
            "rocket", "retina")
TEXTURE_NAMES = ("siemens", "bars", "checker") + _SKIMAGE


def _rgb(gray: np.ndarray) -> np.ndarray:
    return np.repeat(gray[..., None], 3, axis=-1).astype(np.float32)


@renamed_keywords(size="size_px")
def siemens_star(size_px: int = 512, spokes: int = 36) -> np.ndarray:
    """A Siemens star of ``spokes`` black/white pairs, (size_px, size_px, 3) in
    {0.05, 0.95}.

    Parameters
    ----------
    size_px : int, optional
        Side of the image, px (default 512); the star fills the inscribed disk, the
        corners are 0.5. Formerly ``size`` (still accepted, with a DeprecationWarning).
    spokes : int, optional
        Black/white pairs around the centre (default 36).
    """
    y, x = np.mgrid[0:size_px, 0:size_px] + 0.5 - size_px / 2
    ang = np.arctan2(y, x)
    star = (np.sin(spokes * ang) > 0).astype(np.float32)
    r = np.hypot(x, y) / (size_px / 2)
    star = np.where(r > 1.0, 0.5, star)
    return _rgb(0.05 + 0.9 * star)


@renamed_keywords(size="size_px")
def bar_chart(size_px: int = 512) -> np.ndarray:
    """Groups of bars whose period halves from row to row (a 1951-USAF-like chart).

    Parameters
    ----------
    size_px : int, optional
        Side of the (size_px, size_px, 3) image, px (default 512): six rows of bars,
        the first of period ``size_px / 4`` px, the last at least 2 px. Formerly
        ``size`` (still accepted, with a DeprecationWarning).
    """
    img = np.full((size_px, size_px), 0.95, dtype=np.float32)
    rows = 6
    h = size_px // rows
    x = np.arange(size_px)
    for k in range(rows):
        period = max(2, size_px // (4 * 2 ** k))
        bars = ((x // (period // 2 or 1)) % 2 == 0)
        img[k * h + h // 8: (k + 1) * h - h // 8, :] = np.where(bars, 0.05, 0.95)
    return _rgb(img)


@renamed_keywords(size="size_px")
def checkerboard(size_px: int = 512, squares: int = 16) -> np.ndarray:
    """A checkerboard of ``squares`` × ``squares`` squares, (size_px, size_px, 3) in
    {0.1, 0.9}.

    Parameters
    ----------
    size_px : int, optional
        Side of the image, px (default 512). Formerly ``size`` (still accepted, with a
        DeprecationWarning).
    squares : int, optional
        Squares along each side (default 16).
    """
    y, x = np.mgrid[0:size_px, 0:size_px]
    c = ((x * squares // size_px + y * squares // size_px) % 2).astype(np.float32)
    return _rgb(0.1 + 0.8 * c)


@functools.cache
def skimage_texture(name: str) -> np.ndarray:
    """A scikit-image bundled image as linear RGB float32 (H, W, 3).

    Parameters
    ----------
    name : str
        One of scikit-image's bundled images in :data:`TEXTURE_NAMES` (``astronaut``,
        ``camera``, ...); gray ones are repeated into RGB.
    """
    from skimage import data

    if name not in _SKIMAGE:
        raise ValueError(f"texture: unknown scikit-image image {name!r}; "
                         f"known: {', '.join(_SKIMAGE)}")
    img = np.asarray(getattr(data, name)())
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=-1)
    img = img[..., :3]
    scale = 255.0 if img.dtype == np.uint8 else float(max(img.max(), 1e-12))
    return srgb_to_linear(img.astype(np.float32) / scale)


def texture(name: str) -> np.ndarray:
    """Any texture of :data:`TEXTURE_NAMES` as linear RGB float32 (H, W, 3).

    Parameters
    ----------
    name : str
        ``siemens``, ``bars`` or ``checker`` (512 px, default settings) or a
        scikit-image bundled image (:func:`skimage_texture`).
    """
    if name == "siemens":
        return siemens_star()
    if name == "bars":
        return bar_chart()
    if name == "checker":
        return checkerboard()
    return skimage_texture(name)
