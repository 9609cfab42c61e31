"""The band-by-band Wiener solve of the polar deconvolution (steps 2-3) and the
Cartesian disk around the pole.

The bands (:func:`~mitsweep.deconv.polar.bands.band_plan`) run in parallel (NumPy and
scipy.fft release the GIL) and are summed in band order, so that the result does not
depend on the thread count.
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import scipy.fft as sfft

from ..kernels import interpolate_radial
from ..wiener import wiener_deconvolve
from . import spline
from .bands import BandPlan, band_transfer, band_wiener, symmetric_extension
from .grid import PolarGrid

__all__ = ["restore_bands", "restore_centre"]


def _restore_band(spec: np.ndarray, plan: BandPlan, b: int, grid: PolarGrid,
                  kernels: np.ndarray, rad: np.ndarray, *, nsr: float, prior: str,
                  n_px: float, fft_workers: int) -> tuple | None:
    """Band b of ``plan``: its rows lo:hi, harmonics :mc, restored and weighted by its
    window; ``(lo, hi, mc, block, tail)`` with ``tail`` the weighted unfiltered
    harmonics mc: (None when every harmonic is filtered), or None for an empty band."""
    band_b = plan.bands[b]
    if band_b is None:
        return None
    dt = spec.real.dtype
    cdt = spec.dtype
    step = grid.radial_step
    M = spec.shape[1]
    rb = band_b.centre
    (lo, hi), (s0, s1) = band_b.rows, band_b.context
    L, mc = band_b.fft_length, band_b.harmonics
    k_b = interpolate_radial(kernels, rad, rb)
    Hb = band_transfer(k_b, rb, step, L, mc, cdt)
    Gb = band_wiener(Hb, sfft.fftfreq(L, d=step), np.arange(mc) / (2 * math.pi * rb),
                     nsr, prior, n_px)
    # symmetric extension to the FFT length (as in wiener_deconvolve): no step at the
    # slice ends, so smooth content, a constant above all, passes without ringing
    n_s = s1 - s0
    a = (L - n_s) // 2
    ext = symmetric_extension(spec[s0:s1, :mc], a, L - n_s - a)
    band = sfft.fft(ext, axis=0, workers=fft_workers, overwrite_x=True)
    band *= Gb[..., None]
    band = sfft.ifft(band, axis=0, workers=fft_workers, overwrite_x=True)
    w = plan.weights[b, lo:hi, None, None].astype(dt)
    blk = band[lo - s0 + a:hi - s0 + a]
    blk *= w
    return lo, hi, mc, blk, (w * spec[lo:hi, mc:] if mc < M else None)


def restore_bands(spec: np.ndarray, plan: BandPlan, grid: PolarGrid, kernels: np.ndarray,
                  rad: np.ndarray, *, nsr: float, prior: str, n_px: float) -> np.ndarray:
    """Wiener-restore the angle spectrum ``spec`` (n_radii, M, C) band by band.

    Parameters
    ----------
    spec : (n_radii, n_angles // 2 + 1, C) complex ndarray
        rfft along angle of the polar image
        (:func:`~mitsweep.deconv.polar.resample.angle_spectrum`).
    plan : BandPlan
        Where the bands lie (:func:`~mitsweep.deconv.polar.bands.band_plan`).
    grid : PolarGrid
        The polar grid of ``spec``.
    kernels, rad : ndarray
        The bank's kernels at one depth (n_radii_bank, K, K) and their radii (pixels).
    nsr, prior, n_px
        The Wiener regulariser (:func:`~mitsweep.deconv.wiener.regulariser`).

    Returns
    -------
    (n_radii, M, C) complex ndarray
        ``Σ_b w_b x̂_b``: each band's restored rows weighted by its window (rows no band
        writes are 0).
    """
    n_threads = spline.threads()
    fft_workers = 1 if n_threads > 1 else -1        # the bands run in parallel instead

    def restore(b: int):
        return _restore_band(spec, plan, b, grid, kernels, rad, nsr=nsr, prior=prior,
                             n_px=n_px, fft_workers=fft_workers)

    # Bands come in rising rows, each overlapping only the one before: rows are written by
    # the first band that holds them and added to by the next (0 + x = x: the same sum as
    # from zeros)
    acc = np.empty_like(spec)
    done = 0                                   # rows [0, done) hold their first terms
    with ThreadPoolExecutor(n_threads) as pool:
        for res in pool.map(restore, range(len(plan.centres))):
            if res is None:
                continue
            lo, hi, mc, blk, tail = res
            if lo > done:
                acc[done:lo] = 0
            mid = min(max(lo, done), hi)
            acc[lo:mid, :mc] += blk[:mid - lo]
            acc[mid:hi, :mc] = blk[mid - lo:]
            if tail is not None:
                acc[lo:mid, mc:] += tail[:mid - lo]
                acc[mid:hi, mc:] = tail[mid - lo:]
            done = max(done, hi)
    acc[done:] = 0
    return acc


def restore_centre(out: np.ndarray, img: np.ndarray, plan: BandPlan, grid: PolarGrid,
                   kernels: np.ndarray, rad: np.ndarray, *, nsr: float, prior: str,
                   n_px: float) -> np.ndarray:
    """Blend into ``out`` (H, W, C), in place, the disk around the pole restored in
    Cartesian coordinates with the centre IPSF (Wiener), where a polar grid cannot
    describe a kernel: weight 1 inside ``plan.centres[0]``, falling linearly to 0 at
    ``plan.inner_radius``.

    Parameters
    ----------
    out : (H, W, C) ndarray
        The polar restoration, overwritten around the pole.
    img : (H, W, C) ndarray
        The blurred image.
    plan : BandPlan
        The band plan (its inner radius and first centre fix the blend).
    grid : PolarGrid
        The polar grid (its pole is the disk's centre).
    kernels, rad : ndarray
        The bank's kernels at one depth (n_radii_bank, K, K) and their radii (pixels);
        the kernel at radius 0 restores the disk.
    nsr, prior, n_px
        The Wiener regulariser (:func:`~mitsweep.deconv.wiener.regulariser`).
    """
    H, W = img.shape[:2]
    K = kernels.shape[-1]
    dt = out.dtype
    r_in = plan.inner_radius
    cy, cx = grid.center
    half = int(math.ceil(r_in)) + 3 * K
    y0, y1 = max(0, int(cy) - half), min(H, int(cy) + half + 2)
    x0, x1 = max(0, int(cx) - half), min(W, int(cx) + half + 2)
    if y1 - y0 > K and x1 - x0 > K:
        k0 = interpolate_radial(kernels, rad, 0.0)
        cart = wiener_deconvolve(img[y0:y1, x0:x1], k0, nsr=nsr, prior=prior, n_px=n_px)
        yy, xx = np.mgrid[y0:y1, x0:x1]
        rr = np.hypot(yy - cy, xx - cx)
        blend = np.clip((r_in - rr) / (r_in - plan.centres[0]), 0, 1).astype(dt)[..., None]
        out[y0:y1, x0:x1] = blend * cart + (1 - blend) * out[y0:y1, x0:x1]
    return out
