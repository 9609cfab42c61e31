"""The radial bands of the polar deconvolution: where they lie, and their filters.

The radius is cut into overlapping bands with hat windows that sum to one
(:func:`band_plan`, pure: grid, kernel size and spacing in, the plan out); each band is
restored with the Wiener filter (:func:`band_wiener`) of the bank's IPSF interpolated at
its radius, its transfer function evaluated analytically in (radial frequency, angular
harmonic m) (:func:`band_transfer`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import DTypeLike
import scipy.fft as sfft

from ..spatial import hat_weights
from ..wiener import natural_prior_scale, regulariser, wiener_filter
from .grid import SPLINE_PX, PolarGrid

__all__ = ["Band", "BandPlan", "band_plan", "band_length", "band_transfer", "band_wiener",
           "symmetric_extension"]


def band_length(n: int, step: float) -> int:
    """Smallest fast FFT length L >= n with L * step an integer (see band_transfer).

    Parameters
    ----------
    n : int
        Rows to hold at least.
    step : float
        Radial step of the polar grid, px per row.

    Raises
    ------
    ValueError
        No L below 4 n + 64 fits the step.
    """
    L = sfft.next_fast_len(n)
    while L < 4 * n + 64:
        if abs(L * step - round(L * step)) < 1e-9 * L:
            return L
        L = sfft.next_fast_len(L + 1)
    raise ValueError(f"radial step {step} px: no FFT length L >= {n} makes L * step "
                     "an integer; use a radial_oversampling such as 1, 1.25, 1.5 or 2")


def band_transfer(k: np.ndarray, r_band: float, step: float, L: int, M: int,
                  cdt: DTypeLike) -> np.ndarray:
    """Transfer function (L, M) of pixel kernel ``k`` at radius ``r_band`` on the polar grid.

    Axis 0: the radial frequencies of an L-point FFT over rows spaced ``step`` px,
    ν = p / (L step) cycles/px; axis 1: angular harmonics m. The kernel is taken as its
    pixel samples, as in Cartesian Wiener deconvolution: radially its DFT over
    L step pixels gives exactly those ν up to the pixel Nyquist 1/2, and beyond (the
    polar grid is oversampled; only interpolation residue lives there) the value at
    ν = ±1/2 is held. Tangential pixel offset t (kernel rows, upward =
    counter-clockwise) is an angle t / r, so harmonic m sees the phase exp(−i m t / r).

    Parameters
    ----------
    k : (K0, K1) ndarray
        The pixel kernel at the band's radius: axis 0 tangential, axis 1 radial.
    r_band : float
        The band's radius, px.
    step : float
        Radial step of the polar grid, px per row.
    L : int
        Radial FFT length (:func:`band_length`: L · step an integer, at least K1 px).
    M : int
        Angular harmonics to compute (0..M-1).
    cdt : complex64 or complex128
        The output's dtype (and, by its real part, the arithmetic's precision).

    Returns
    -------
    (L, M) ndarray
        The transfer function, 1 at DC.
    """
    K0, K1 = k.shape
    rdt: type[np.floating] = np.float32 if np.dtype(cdt) == np.complex64 else np.float64
    kt: np.ndarray = k.astype(rdt)
    h0 = K0 // 2
    if K0 % 2:
        # rows h0 ∓ t hold offsets ±t: cos is even and sin odd in t, so the sums run over
        # t >= 0 on the even and odd parts of the kernel (half the trigonometry)
        up, down = kt[h0::-1], kt[h0:]                       # offsets +t, -t (t = 0..h0)
        k_even = up + down
        k_even[0] = kt[h0]
        k_odd = (up - down)[1:]
        t = np.arange(h0 + 1, dtype=rdt)
    else:
        k_even = k_odd = kt
        t = -(np.arange(K0) - h0).astype(rdt)                # tangential offset, px
    phase = np.outer(t, np.arange(M, dtype=rdt) / rdt(max(r_band, 1e-9)))   # (t, M)
    T: np.ndarray = np.empty((K1, M), dtype=cdt)             # radial offset s × harmonic m
    # einsum, not BLAS: for these thin products a threaded BLAS on a busy machine costs
    # 3-5x more in thread start-up than the arithmetic (measured)
    T.real = np.einsum("ts,tm->sm", k_even, np.cos(phase), optimize=False)
    odd_phase = phase[1:] if K0 % 2 else phase
    T.imag = -np.einsum("ts,tm->sm", k_odd, np.sin(odd_phase), optimize=False)
    L_px = int(round(L * step))
    if L_px < K1:
        raise ValueError(f"band of {L} rows is shorter than the kernel ({K1} px)")
    T /= T[:, 0].real.sum()                                  # H = 1 at DC
    big: np.ndarray = np.zeros((L_px, M), dtype=cdt)
    h = K1 // 2
    big[:h + 1] = T[h:]
    if h:
        big[-h:] = T[:h]
    H_px = sfft.fft(big, axis=0, workers=1, overwrite_x=True)
    # row p of the L-point FFT (signed p: ν = p / L_px) reads H_px at p clipped to the
    # pixel Nyquist: the rows in reach are slices of H_px, the others its end rows
    hp, hn = (L_px - 1) // 2, L_px // 2          # highest positive, negative numerators
    n_pos = (L + 1) // 2                         # rows with p >= 0
    out: np.ndarray = np.empty((L, M), dtype=cdt)
    out[:hp + 1] = H_px[:hp + 1]
    out[hp + 1:n_pos] = H_px[hp]
    out[n_pos:L - hn] = H_px[L_px - hn]
    out[L - hn:] = H_px[L_px - hn:]
    return out


def band_wiener(Hb: np.ndarray, nu: np.ndarray, ft: np.ndarray, nsr: float, prior: str,
                 n_px: float) -> np.ndarray:
    """The Wiener filter of a band, computed in place of its transfer function ``Hb``
    (L, mc): what ``wiener_filter(Hb, regulariser(..., freqs=(nu, ft)))`` gives, in
    fewer passes over the band. ``nu`` (L,) radial and ``ft`` (mc,) tangential
    frequencies, cycles/px; R = 0 at DC (where H = 1), so a constant passes unchanged.

    Parameters
    ----------
    Hb : (L, mc) complex ndarray
        The band's transfer function (:func:`band_transfer`); overwritten with the filter.
    nu : (L,) ndarray
        Radial frequencies of the rows, cycles/px.
    ft : (mc,) ndarray
        Tangential frequencies of the harmonics, cycles/px.
    nsr : float
        Noise-to-signal ratio, >= 0.
    prior : {"natural", "constant"}
        The regulariser, as in :func:`~mitsweep.deconv.wiener.regulariser`.
    n_px : float
        Size of the whole image, px, for the natural prior's scale.
    """
    if not nsr > 0 or prior not in ("natural", "constant"):
        return wiener_filter(Hb, regulariser(Hb.shape, nsr, prior, dtype=Hb.real.dtype,
                                             freqs=(nu[:, None], ft[None, :]), n_px=n_px))
    den = Hb.real * Hb.real
    den += Hb.imag * Hb.imag
    if prior == "natural":
        a = nsr * natural_prior_scale(n_px)
        den += (a * nu * nu).astype(den.dtype)[:, None]
        den += (a * ft * ft).astype(den.dtype)[None, :]
    else:
        den[0, 0] -= den.dtype.type(nsr)                # so that R = 0 at DC
        den += den.dtype.type(nsr)
    # |H|^2 + R > 0 everywhere: R > 0 off DC, |H| = 1 at DC. G = conj(H) / den, as
    # real products on the two parts (a complex division costs several times more)
    np.reciprocal(den, out=den)
    re, im = Hb.real, Hb.imag
    re *= den
    np.negative(den, out=den)
    im *= den
    return Hb


def symmetric_extension(x: np.ndarray, before: int, after: int) -> np.ndarray:
    """``np.pad(x, [(before, after), (0, 0), ...], mode="symmetric")`` along axis 0,
    written into one new array (np.pad's general path costs several extra passes).

    Parameters
    ----------
    x : ndarray
        The array to extend along axis 0.
    before, after : int
        Rows added before and after, >= 0.
    """
    n = x.shape[0]
    if before > n or after > n:
        return np.pad(x, [(before, after)] + [(0, 0)] * (x.ndim - 1), mode="symmetric")
    out = np.empty((before + n + after,) + x.shape[1:], dtype=x.dtype)
    out[before:before + n] = x
    if before:
        out[:before] = x[:before][::-1]
    if after:
        out[before + n:] = x[::-1][:after]
    return out


@dataclass(frozen=True)
class Band:
    """One radial band of a :class:`BandPlan` (rows are polar-grid rows).

    Attributes
    ----------
    centre : float
        Radius the band's IPSF and angular scale are taken at, pixels.
    rows : (lo, hi)
        Rows the band writes: where its window is non-zero, within the rows the
        Cartesian pixels read.
    context : (s0, s1)
        Rows it filters: ``rows`` plus the margin on either side, within the grid.
    fft_length : int
        Radial FFT length L >= s1 - s0 with L · step an integer (:func:`band_length`).
    harmonics : int
        Angular harmonics filtered (``:harmonics``); the others pass unfiltered.
    """

    centre: float
    rows: tuple[int, int]
    context: tuple[int, int]
    fft_length: int
    harmonics: int


@dataclass(frozen=True)
class BandPlan:
    """Where the bands of a polar deconvolution lie (:func:`band_plan`).

    Attributes
    ----------
    inner_radius : float
        Radius of the disk around the pole restored in Cartesian coordinates, pixels.
    centres : (n_b,) ndarray
        Band centres, pixels, rising.
    weights : (n_b, n_radii) ndarray
        Hat windows over the grid's rows (:func:`mitsweep.deconv.spatial.hat_weights`):
        they sum to one on every row between the first and the last centre.
    bands : tuple of Band or None
        Per centre; None where the band writes no row the pixels read.
    """

    inner_radius: float
    centres: np.ndarray
    weights: np.ndarray
    bands: tuple[Band | None, ...]


def band_plan(grid: PolarGrid, kernel_size: int, *, band_spacing: float = 0.25,
              margin: int | None = None) -> BandPlan:
    """The radial bands for a kernel of ``kernel_size`` (K) pixels on ``grid``.

    Band centres start at half the inner disk's radius ``r_in = max(2K, 8)`` and step by
    ``max(band_spacing · r, K)`` (a band every 25 % of radius by default, at least one
    kernel apart); the last sits at ``r_max`` (at least 1 px beyond the one before).
    Each band filters its rows plus ``margin`` pixels of context (default ``ceil(1.5
    K)``) on either side, and the harmonics a pixel image holds at its outer radius
    (tangential frequency up to the diagonal Nyquist 1/√2 cycles/px, plus 8).

    Pure: no image, no kernel values; the same plan for the same grid and arguments.

    Parameters
    ----------
    grid : PolarGrid
        The polar grid of the image.
    kernel_size : int
        Side K of the kernels, px.
    band_spacing : float
        Distance between band centres as a fraction of their radius (default 0.25).
    margin : int, optional
        Context on either side of a band's rows, px (default ``ceil(1.5 K)``).

    Raises
    ------
    ValueError
        No FFT length fits the radial step (:func:`band_length`).
    """
    K = int(kernel_size)
    step = grid.radial_step
    r_in = max(2.0 * K, 8.0)                   # Cartesian disk around the pole
    spaced = [r_in / 2]
    while spaced[-1] < grid.r_max:
        spaced.append(spaced[-1] + max(band_spacing * spaced[-1], float(K)))
    spaced[-1] = max(min(spaced[-1], grid.r_max), spaced[-2] + 1.0)
    centres = np.asarray(spaced)
    weights = hat_weights(grid.radii, centres)                         # (n_b, n_r)
    m_px = int(math.ceil(1.5 * K)) if margin is None else int(margin)
    m_rows = int(math.ceil(m_px / step))
    # rows that the Cartesian pixels read (a spline's reach around [0, r_max])
    keep0 = int(math.floor(grid.row_of(-SPLINE_PX)))
    keep1 = int(math.ceil(grid.row_of(grid.r_max + SPLINE_PX))) + 1
    n_r, M = grid.n_radii, grid.n_angles // 2 + 1
    bands: list[Band | None] = []
    for rb, w in zip(centres, weights):
        nz = np.flatnonzero(w > 0)
        lo, hi = max(int(nz[0]), keep0), min(int(nz[-1]) + 1, keep1)
        if hi <= lo:
            bands.append(None)
            continue
        # below row 0 and beyond the grid's end the symmetric extension stands in for
        # the context (the disk r < r_in is restored in Cartesian coordinates anyway,
        # and beyond r_max lies the dark rim of the mirror's image)
        s0, s1 = max(0, lo - m_rows), min(n_r, hi + m_rows)
        # harmonics above the pixel grid's reach at the slice's outer radius (tangential
        # frequency m / 2πr beyond the diagonal Nyquist 1/√2 cycles/px) hold only
        # interpolation residue: they pass unfiltered, which also saves the inner
        # bands most of their work
        r_hi = max(float(grid.radii[s1 - 1]), rb)
        mc = int(min(M, math.ceil(2 * math.pi * r_hi / math.sqrt(2)) + 8))
        bands.append(Band(centre=float(rb), rows=(lo, hi), context=(s0, s1),
                          fft_length=band_length(s1 - s0, step), harmonics=mc))
    return BandPlan(inner_radius=r_in, centres=centres, weights=weights, bands=tuple(bands))
