"""What the photo shows, as the rim search needs it: luminance, the renderer's void,
smoothing, reduction, fine-detail energy and the noise level."""

from __future__ import annotations

import numpy as np

__all__ = ["luminance", "photo_void", "fill_void", "smooth", "reduce_by", "texture_energy",
           "noise_sigma", "VOID_ZERO_SHARE", "VOID_MARGIN_PX", "TEXTURE_SCALE_PX"]

#: Scale (px) of the fine detail whose local energy is the coarse search's second cue.
TEXTURE_SCALE_PX = 1.0
#: Share of exact zeros (all channels) in a 5x5 neighbourhood from which a pixel is
#: outside the photo (:func:`photo_void`): what a renderer skipped (``mitsweep render``
#: writes only the mirror's window) is exactly zero, and stays half zero after a
#: sub-pixel shift (the negative ringing clips to 0); a photographed scene is not.
VOID_ZERO_SHARE = 0.4
#: Pixels added around the void: the ringing of a shifted window's border.
VOID_MARGIN_PX = 2


def luminance(image: np.ndarray) -> np.ndarray:
    """Linear luminance (H, W) float64 of an (H, W) or (H, W, 3) linear image
    (Rec. 709 weights; a grey image is returned as is)."""
    a = np.asarray(image, dtype=np.float64)
    if a.ndim == 2:
        return a
    return a[..., :3] @ np.array([0.2126, 0.7152, 0.0722])


def photo_void(image: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels outside what the photo shows, the renderer's skipped pixels.

    Where at least :data:`VOID_ZERO_SHARE` of a 5x5 neighbourhood is exactly zero in
    every channel, in regions wider than 3 px, grown by :data:`VOID_MARGIN_PX`. A render
    cropped to the mirror's window (black from 8 px outside the rim) has a strong
    straight edge beside the rim there, which is not the photo's content: the rim fit
    treats the void as unknown (:func:`fit_rim`). A photo without exact zeros has none.
    """
    from scipy.ndimage import binary_dilation, binary_opening, uniform_filter

    a = np.asarray(image)
    zero = (a == 0) if a.ndim == 2 else np.all(a == 0, axis=-1)
    if not zero.any():
        return zero
    void = uniform_filter(zero.astype(np.float64), 5, mode="nearest") >= VOID_ZERO_SHARE
    void = binary_opening(void, np.ones((3, 3), bool), iterations=1)
    if VOID_MARGIN_PX > 0 and void.any():
        void = binary_dilation(void, np.ones((3, 3), bool), iterations=VOID_MARGIN_PX)
    return void


def fill_void(lum: np.ndarray, void: np.ndarray) -> np.ndarray:
    """``lum`` with each void pixel set to its nearest shown pixel's value: the void's
    border is then no edge (the profiles and orientation fields see nothing there)."""
    from scipy.ndimage import distance_transform_edt

    if not void.any() or void.all():
        return lum
    _, (ii, jj) = distance_transform_edt(void, return_indices=True)
    return lum[ii, jj]


def smooth(img: np.ndarray, sigma: float) -> np.ndarray:
    from scipy.ndimage import gaussian_filter

    return gaussian_filter(img, sigma, mode="nearest") if sigma > 0 else img


def reduce_by(img: np.ndarray, factor: int) -> np.ndarray:
    if factor <= 1:
        return img
    H, W = (img.shape[0] // factor) * factor, (img.shape[1] // factor) * factor
    return img[:H, :W].reshape(H // factor, factor, W // factor, factor).mean(axis=(1, 3))


def texture_energy(lum: np.ndarray) -> np.ndarray:
    """Local RMS (H, W) of the image's fine detail: the high-pass at
    :data:`TEXTURE_SCALE_PX`, its square smoothed over the same scale."""
    detail = lum - smooth(lum, TEXTURE_SCALE_PX)
    return np.sqrt(smooth(detail * detail, TEXTURE_SCALE_PX))


def noise_sigma(lum: np.ndarray, shown: np.ndarray | None = None) -> float:
    """Robust per-pixel noise estimate (MAD of the diagonal second difference), over
    the 2x2 blocks the photo shows (all of them by default)."""
    d = lum[1:, 1:] - lum[:-1, 1:] - lum[1:, :-1] + lum[:-1, :-1]
    if shown is not None:
        block = shown[1:, 1:] & shown[:-1, 1:] & shown[1:, :-1] & shown[:-1, :-1]
        if block.any():
            d = d[block]
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / 2.0)
