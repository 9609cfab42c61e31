"""What the photo shows, as the rim search needs it: luminance, the renderer's void,
smoothing, reduction, fine-detail energy and the noise level."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["luminance", "photo_void", "fill_void", "smooth", "reduce_by", "texture_energy",
           "noise_sigma", "VOID_ZERO_SHARE", "VOID_MARGIN_PX", "TEXTURE_SCALE_PX"]

#: Pixels above which :func:`noise_sigma` estimates from a regular subset of row pairs.
NOISE_SAMPLE_PIXELS = 4_000_000

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
    (Rec. 709 weights; a grey image is returned as is).

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
        A linear image; of ``C >= 3`` channels the first three are R, G, B.
    """
    a = np.asarray(image)
    if a.ndim == 2:
        return a.astype(np.float64, copy=False)
    if a.dtype == np.float32:  # a photo as read: weighted in float32 (no float64 copy of
        # the three channels, 0.6 GB at 24 MP), then widened; ~1e-7 relative
        return (a[..., :3] @ np.array([0.2126, 0.7152, 0.0722], np.float32)).astype(
            np.float64)
    return np.asarray(a[..., :3], dtype=np.float64) @ np.array([0.2126, 0.7152, 0.0722])


def photo_void(image: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels outside what the photo shows, the renderer's skipped pixels.

    Where at least :data:`VOID_ZERO_SHARE` of a 5x5 neighbourhood is exactly zero in
    every channel, in regions wider than 3 px, grown by :data:`VOID_MARGIN_PX`. A render
    cropped to the mirror's window (black from 8 px outside the rim) has a strong
    straight edge beside the rim there, which is not the photo's content: the rim fit
    treats the void as unknown (:func:`fit_rim`). A photo without exact zeros has none.

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
        The photo as read (exact zeros mark a render's skipped pixels).
    """
    from scipy.ndimage import binary_dilation, binary_opening, uniform_filter

    a = np.asarray(image)
    zero = (a == 0) if a.ndim == 2 else np.all(a == 0, axis=-1)
    if not zero.any():
        return zero
    # Every step is local (a 5x5 mean, a 3x3 opening, VOID_MARGIN_PX dilations): only
    # the zeros' bounding box, grown by their reach, can become void, and the box's
    # border then sees what the whole frame would (no zeros lie beyond it).
    reach = 2 + 2 + VOID_MARGIN_PX + 1
    rows, cols = np.flatnonzero(zero.any(axis=1)), np.flatnonzero(zero.any(axis=0))
    r0, r1 = max(rows[0] - reach, 0), min(rows[-1] + reach + 1, zero.shape[0])
    c0, c1 = max(cols[0] - reach, 0), min(cols[-1] + reach + 1, zero.shape[1])
    box = uniform_filter(zero[r0:r1, c0:c1].astype(np.float64), 5, mode="nearest") \
        >= VOID_ZERO_SHARE
    box = binary_opening(box, np.ones((3, 3), bool), iterations=1)
    if VOID_MARGIN_PX > 0 and box.any():
        box = binary_dilation(box, np.ones((3, 3), bool), iterations=VOID_MARGIN_PX)
    void = np.zeros_like(zero)
    void[r0:r1, c0:c1] = box
    return void


def fill_void(lum: np.ndarray, void: np.ndarray) -> np.ndarray:
    """``lum`` with each void pixel set to its nearest shown pixel's value: the void's
    border is then no edge (the profiles and orientation fields see nothing there).

    Parameters
    ----------
    lum : (H, W) ndarray
        Luminance.
    void : (H, W) bool ndarray
        Pixels the photo does not show (:func:`photo_void`).
    """
    from scipy.ndimage import distance_transform_edt

    if not void.any() or void.all():
        return lum
    # Only the void's bounding box, grown by a pixel, is transformed: a void pixel's
    # nearest shown pixel lies in it (the box's border ring is shown, and a shown pixel
    # beyond the ring is farther than where the segment to it crosses the ring). A few
    # clipped-black pixels in a 24 MP photo then cost a small box, not the whole frame.
    rows, cols = np.flatnonzero(void.any(axis=1)), np.flatnonzero(void.any(axis=0))
    r0, r1 = max(rows[0] - 1, 0), min(rows[-1] + 2, void.shape[0])
    c0, c1 = max(cols[0] - 1, 0), min(cols[-1] + 2, void.shape[1])
    box = void[r0:r1, c0:c1]
    if box.all():  # the void fills its box: the nearest shown pixel is beyond it
        r0, r1, c0, c1 = 0, void.shape[0], 0, void.shape[1]
        box = void
    _, (ii, jj) = distance_transform_edt(box, return_indices=True)
    out = lum.copy()
    out[r0:r1, c0:c1] = lum[r0:r1, c0:c1][ii, jj]
    return out


def smooth(img: np.ndarray, sigma: float) -> np.ndarray:
    """``img`` smoothed by a Gaussian of standard deviation ``sigma`` px.

    Parameters
    ----------
    img : (H, W) ndarray
        Image to smooth.
    sigma : float
        Gaussian standard deviation, px (0 or less: ``img`` itself). Edges are extended
        with their nearest value.
    """
    from scipy.ndimage import gaussian_filter

    return gaussian_filter(img, sigma, mode="nearest") if sigma > 0 else img


def reduce_by(img: np.ndarray, factor: int) -> np.ndarray:
    """``img`` reduced by block means of ``factor`` × ``factor`` pixels.

    Parameters
    ----------
    img : (H, W) ndarray
        Image to reduce.
    factor : int
        Block size: each output pixel is the mean of ``factor`` × ``factor`` input pixels
        (rows and columns beyond a whole block are dropped; 1 or less: ``img`` itself).
    """
    if factor <= 1:
        return img
    H, W = (img.shape[0] // factor) * factor, (img.shape[1] // factor) * factor
    return img[:H, :W].reshape(H // factor, factor, W // factor, factor).mean(axis=(1, 3))


def texture_energy(lum: np.ndarray) -> np.ndarray:
    """Local RMS (H, W) of the image's fine detail: the high-pass at
    :data:`TEXTURE_SCALE_PX`, its square smoothed over the same scale.

    Parameters
    ----------
    lum : (H, W) ndarray
        Luminance.
    """
    detail = lum - smooth(lum, TEXTURE_SCALE_PX)
    return np.sqrt(smooth(detail * detail, TEXTURE_SCALE_PX))


def noise_sigma(lum: np.ndarray, shown: np.ndarray | None = None) -> float:
    """Robust per-pixel noise estimate (MAD of the diagonal second difference), over
    the 2x2 blocks the photo shows (all of them by default).

    Parameters
    ----------
    lum : (H, W) ndarray
        Luminance.
    shown : (H, W) bool ndarray, optional
        Pixels the photo shows; blocks touching others are left out.
    """
    if lum.size > NOISE_SAMPLE_PIXELS:  # a regular subset of rows: the MAD of millions
        # of differences is known to ~0.1% from one million
        stride = int(math.ceil(lum.size / NOISE_SAMPLE_PIXELS))
        starts = np.arange(0, lum.shape[0] - 1, stride)
        pairs = np.stack([starts, starts + 1], axis=1).ravel()
        lum = lum[pairs]
        shown = None if shown is None else shown[pairs]
        d = (lum[1::2, 1:] - lum[0::2, 1:] - lum[1::2, :-1] + lum[0::2, :-1])
        if shown is not None:
            block = shown[1::2, 1:] & shown[0::2, 1:] & shown[1::2, :-1] & shown[0::2, :-1]
            if block.any():
                d = d[block]
        return float(1.4826 * np.median(np.abs(d - np.median(d))) / 2.0)
    d = lum[1:, 1:] - lum[:-1, 1:] - lum[1:, :-1] + lum[:-1, :-1]
    if shown is not None:
        block = shown[1:, 1:] & shown[:-1, 1:] & shown[1:, :-1] & shown[:-1, :-1]
        if block.any():
            d = d[block]
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / 2.0)
