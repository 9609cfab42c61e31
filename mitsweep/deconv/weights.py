r"""Wiener's NSR from what is known about an image: its noise model and its spectrum.

The natural-image Wiener filter (:func:`~mitsweep.deconv.wiener.regulariser`,
``prior="natural"``) regularises with :math:`R(f) = \nu\, c(f)`,
:math:`c(f) = 2\pi\ln(n/2)\,|f|^2`: the Wiener ratio :math:`\sigma_n^2/S(f)` for a sharp
image of power spectrum :math:`S(f) = A/|f|^2` and white noise of variance
:math:`\sigma_n^2`, with :math:`\nu = \sigma_n^2/\sigma_s^2` and
:math:`\sigma_s^2 = 2\pi A\ln(n/2)` that spectrum's variance
(:func:`~mitsweep.deconv.wiener.natural_prior_scale`; n the deconvolver's √(HW)).

**The noise** :math:`\sigma_n^2` (:func:`noise_variance`). With a sensor model
(:class:`~mitsweep.deconv.noise.SensorNoise`) a pixel at relative exposure :math:`x` has
the variance :math:`v(x) = (xJ + \sigma_r^2 + (\sigma_{adc}^2 + 1/12)/g^2)/J^2` (shot,
read, ADC, quantisation; J electrons at exposure 1, g the gain). Pixels are independent,
so the noise is white with the power :math:`\overline{v(x)}` over the pixels, and as
:math:`v` is affine in x that is :math:`v(\bar x)` at the mean exposure: signal-dependent
noise enters at the image's own exposure and light level. Without a model, the wavelet
estimate (:func:`~mitsweep.deconv.wiener.estimate_noise_sigma`), capped by the
periodogram's floor at the highest frequencies (where the blur leaves only noise; the
wavelet band alone also holds the finest detail of a sharp centre).

**The signal** is *not* summed into one variance. Natural images fall faster than
:math:`1/|f|^2` at high frequencies (on the bench mosaic the variance-based
:math:`\sigma_s^2` is 3.3 times the one the oracle NSR implies), and the scalar matters
only where signal and noise cross. So :math:`\nu` is the one that minimises the
restoration's expected squared error under the image's measured spectrum
(:func:`wiener_risk`): for a bank of kernels :math:`K_b`, each blurring a share
:math:`w_b` of the pixels restored (:func:`kernel_shares`), and a sharp spectrum
:math:`S(f)`, the local Wiener filters :math:`G_b = K_b^*/(|K_b|^2 + \nu c)` err by

.. math:: \mathrm{MSE}(\nu) = \sum_b w_b \int \frac{(\nu c)^2\, S(f)
          + |K_b|^2 \sigma_n^2}{(|K_b|^2 + \nu c)^2}\, df ,

and :math:`S` is read off the observed image: its periodogram, averaged over rings of
:math:`|f|`, is :math:`P(f) = \bar H^2(f)\, S(f) + \sigma_n^2` with
:math:`\bar H^2 = \sum_b w_b |K_b|^2` (the product-convolution model: the spectrum of a
patchwork is the area-weighted mean of the patches'), so
:math:`S = \max(P - \sigma_n^2, 0)/\bar H^2`. The periodogram is taken over the whole
frame (:func:`model_nsr`'s ``spectrum="frame"``, the default), where the blur of the
mirror's edge is the model's, or over the pixels restored (``spectrum="mirror"``):
through a taper inside the mirror's image (:func:`spectrum_window`), whose smooth edge
adds no step to read as signal (a hard mask's would, at every frequency). One FFT of
the image and a few dozen sums on a small frequency grid: about 0.1 s at 512².

This is :math:`\nu` chosen by the same criterion as the oracle (the error against the
truth), with the truth's spectrum estimated instead of known; on the bench's
independent blur it lands within 0.05 dB of the oracle (:mod:`mitsweep.deconv.weight_bench`).
"""

from __future__ import annotations

import functools
import json
import logging
import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.fft as sfft
from threadpoolctl import threadpool_limits

from ..deprecation import renamed_keywords
from ..io.bank import BankError, IPSFBank
from ..optics.pixels import optical_center_px
from .kernels import radii_px, select_depth
from .noise import SensorNoise
from .wiener import (DEFAULT_NSR_FLOOR, MAX_NSR, estimate_noise_sigma, fast_shape,
                     natural_prior_scale)

__all__ = ["noise_variance", "kernel_shares", "ring_spectrum", "ring_average",
           "spectrum_window", "mismatch_share", "MismatchProfile", "calibrate_mismatch",
           "wiener_risk", "model_nsr",
           "blind_nsr", "blind_noise_variance", "high_frequency_floor",
           "unexplained_variance"]

logger = logging.getLogger(__name__)


def _planes(image: np.ndarray) -> list[np.ndarray]:
    x = np.asarray(image, dtype=np.float64)
    if x.ndim == 2:
        return [x]
    if x.ndim == 3:
        return [x[..., c] for c in range(x.shape[2])]
    raise ValueError(f"image must be (H, W) or (H, W, C), got shape {x.shape}")


def _mask(image: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
    shape = np.shape(image)[:2]
    if mask is None:
        return np.ones(shape, dtype=bool)
    m = np.asarray(mask, dtype=bool)
    if m.shape != shape:
        raise ValueError(f"mask must be {shape}, got {m.shape}")
    if not m.any():
        raise ValueError("mask selects no pixel")
    return m


def noise_variance(image: np.ndarray, noise: SensorNoise | float | None = None, *,
                   mask: np.ndarray | None = None, level: float = 1.0) -> float:
    r"""Mean noise variance per pixel of ``image`` over ``mask``, in the image's units².

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
    noise : SensorNoise, float or None
        A sensor model (its relative exposure 1.0 is ``level`` in the image's units):
        :math:`\text{level}^2\, v(\bar x)` with :math:`\bar x` the mean exposure over the
        mask (:meth:`SensorNoise.variance` is affine in the exposure, so this is the mean
        of the pixels' variances; negative values, which no light makes, count as 0).
        A float: the noise σ itself. None: the wavelet estimate of the image
        (:func:`~mitsweep.deconv.wiener.estimate_noise_sigma`, channels pooled).
    mask : (H, W) bool ndarray, optional
        The pixels restored (the mirror's image); default all.
    level : float
        Image value of relative exposure 1.0 (a dataset's white level).
    """
    m = _mask(image, mask)
    if noise is None:
        return float(estimate_noise_sigma(np.asarray(image))) ** 2
    if isinstance(noise, (int, float, np.floating, np.integer)):
        s = float(noise)
        if not (math.isfinite(s) and s >= 0):
            raise ValueError(f"noise sigma must be a finite number >= 0, got {noise!r}")
        return s * s
    if not isinstance(noise, SensorNoise):
        raise ValueError(f"noise must be a SensorNoise, a sigma or None, got {noise!r}")
    lv = float(level)
    if not (math.isfinite(lv) and lv > 0):
        raise ValueError(f"level must be a finite number > 0, got {level!r}")
    xs = [float(np.mean(np.clip(p[m], 0, None))) / lv for p in _planes(image)]
    return float(np.mean([noise.variance(x) for x in xs])) * lv * lv


def _one_blas_thread(fn):
    """Run ``fn`` on one BLAS thread: its sums (``einsum``, ``tensordot``, ``dot``) then
    add in one order, so the NSR is the same to the bit in a serial run, a process pool
    and a Dask worker (measured: 1 and 2 OpenBLAS threads differ in the 9th digit, which
    changed a dataset's EDOF bytes between executors)."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with threadpool_limits(limits=1, user_api="blas"):
            return fn(*args, **kwargs)
    return wrapper


@_one_blas_thread
def kernel_shares(bank: IPSFBank, image_shape: tuple[int, ...], *,
                  mask: np.ndarray | None = None,
                  center: tuple[float, float] | None = None,
                  stand_ins: bool = True) -> np.ndarray:
    """The share of the ``mask``'s pixels each kernel of ``bank`` blurs (sums to 1).

    Radial bank: each pixel's radius from ``center`` (default the optical axis) shared
    between its two neighbouring bank radii by linear interpolation, the end kernels
    holding beyond (as :func:`~mitsweep.deconv.polar.polar_deconvolve` does); grid bank:
    the product-convolution's hat windows (a node whose chief ray misses the mirror
    keeps its share: the deconvolution applies its stand-in delta kernel there).

    Parameters
    ----------
    bank : IPSFBank
        A radial or grid bank.
    image_shape : tuple of int
        The image's (H, W[, C]).
    mask : (H, W) bool ndarray, optional
        The pixels restored (default all).
    center : (float, float), optional
        The pole (row, col), px, of a radial bank (default the optical axis).
    stand_ins : bool
        Count the nodes whose chief ray misses the mirror (``metadata["valid"]``
        False; the deconvolution's delta stand-ins), as the restoration applies them
        (default). False: only the traced kernels, each share renormalised: the blur
        the image itself holds (where no node is valid, as True).
    """
    from .spatial import grid_axes_px, hat_weights

    shape = (int(image_shape[0]), int(image_shape[1]))
    m = np.ones(shape, bool) if mask is None else np.asarray(mask, bool)
    ys, xs = np.nonzero(m)
    if bank.kind == "radial":
        cy, cx = optical_center_px(shape) if center is None else center
        rad = radii_px(bank)
        order = np.argsort(rad)
        w = hat_weights(np.hypot(ys - cy, xs - cx), rad[order]).sum(axis=1)
        out = np.zeros(len(rad))
        out[order] = w
    elif bank.kind == "grid":
        rows, cols = grid_axes_px(bank, shape)
        wy = hat_weights(np.arange(shape[0]), rows)      # (n_rows, H)
        wx = hat_weights(np.arange(shape[1]), cols)      # (n_cols, W)
        # sum over the mask of wy[i, y] wx[j, x]
        out = np.einsum("iy,yx,jx->ij", wy, m.astype(np.float64), wx).ravel()
    else:
        raise BankError(f"unknown bank kind {bank.kind!r}")
    valid = bank.metadata.get("valid") if not stand_ins else None
    if valid is not None and len(valid) == len(out):
        traced = np.where(np.asarray(valid, dtype=bool), out, 0.0)
        if traced.sum() > 0:
            out = traced
    return out / out.sum()


def ring_spectrum(image: np.ndarray, *, n_rings: int = 48,
                  window: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The mean-removed image's periodogram per pixel, averaged over rings of ``|f|``.

    Returns ``(f, power)``: each non-empty ring's mean frequency (cycles/pixel) and
    mean ``|FFT|² / (H W)`` (channels averaged), so that white noise of variance σ²
    reads σ² at every ring.

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
        The image.
    n_rings : int
        Rings of equal width from 0 to the highest ``|f|`` (default 48).
    window : (H, W) ndarray, optional
        A taper (values in [0, 1]) over the pixels whose spectrum is wanted
        (:func:`spectrum_window`): the image less its window-weighted mean, times the
        window, with the periodogram divided by the window's mean square so that white
        noise still reads σ². Default: the whole frame.
    """
    planes = _planes(image)
    H, W = planes[0].shape
    M, N = fast_shape((H, W), (0, 0))
    if window is None:
        win, norm = None, float(H * W)
    else:
        win = np.asarray(window, dtype=np.float64)
        if win.shape != (H, W) or not np.all(np.isfinite(win)) or win.min() < 0 \
                or not win.any():
            raise ValueError(f"window must be a finite, non-negative ({H}, {W}) array "
                             "with some weight")
        norm = float(np.sum(win * win))
    P = np.zeros((M, N // 2 + 1))
    for p in planes:
        q = p - p.mean() if win is None else (p - np.sum(p * win) / np.sum(win)) * win
        P = P + np.abs(sfft.rfft2(q, s=(M, N), workers=-1)) ** 2 / norm
    P = P / len(planes)
    fy, fx = sfft.fftfreq(M)[:, None], sfft.rfftfreq(N)[None, :]
    f = np.hypot(fy, fx)
    wcol = np.full(P.shape[1], 2.0)            # rfft half plane: inner columns count twice
    wcol[0] = 1.0
    if N % 2 == 0:
        wcol[-1] = 1.0
    w = np.broadcast_to(wcol[None, :], P.shape)
    edges = np.linspace(0.0, float(f.max()) * (1 + 1e-9), int(n_rings) + 1)
    idx = np.clip(np.searchsorted(edges, f, side="right") - 1, 0, int(n_rings) - 1).ravel()
    cnt = np.bincount(idx, weights=w.ravel(), minlength=n_rings)
    pw = np.bincount(idx, weights=(w * P).ravel(), minlength=n_rings)
    fw = np.bincount(idx, weights=(w * f).ravel(), minlength=n_rings)
    ok = cnt > 0
    return fw[ok] / cnt[ok], pw[ok] / cnt[ok]


def spectrum_window(mask: np.ndarray, *, taper_px: float = 4.0) -> np.ndarray:
    """A taper over ``mask`` for :func:`ring_spectrum`: the mask eroded by
    3 ``taper_px``, smoothed by a Gaussian of σ = ``taper_px`` and cut to the mask, so
    that its edge adds no step (a hard mask's edge reads as signal at every frequency)
    and nothing outside the mask leaks in. Falls back to the mask itself where the
    erosion leaves nothing.

    Parameters
    ----------
    mask : (H, W) bool ndarray
        The pixels restored (the mirror's image).
    taper_px : float
        The taper's width, px (default 4).
    """
    from scipy import ndimage

    m = np.asarray(mask, dtype=bool)
    core = ndimage.binary_erosion(m, iterations=max(int(round(3 * taper_px)), 1))
    if not core.any():
        return m.astype(np.float64)
    return ndimage.gaussian_filter(core.astype(np.float64), float(taper_px)) * m


def ring_average(values: np.ndarray, f: np.ndarray) -> np.ndarray:
    """``values`` on an FFT grid (``(M, N)``, full ``fft2`` layout, frequencies of
    :func:`scipy.fft.fftfreq`) averaged over the rings of :func:`ring_spectrum` whose
    mean frequencies are ``f`` (each grid frequency to the ring whose centre it is
    nearest; a ring that no grid frequency reaches takes its neighbours' value).

    Parameters
    ----------
    values : (M, N) ndarray
        A function of frequency on the FFT grid (a kernel's ``|K|²``).
    f : (n,) ndarray
        The rings' mean frequencies, cycles/px, increasing.
    """
    v = np.asarray(values, dtype=np.float64)
    fq0, fq1 = sfft.fftfreq(v.shape[0]), sfft.fftfreq(v.shape[1])
    fr = np.hypot(fq0[:, None], fq1[None, :]).ravel()
    f = np.asarray(f, dtype=np.float64)
    edges = np.r_[0.0, (f[:-1] + f[1:]) / 2, max(float(fr.max()), float(f[-1])) + 1e-9]
    idx = np.clip(np.searchsorted(edges, fr, side="right") - 1, 0, len(f) - 1)
    cnt = np.bincount(idx, minlength=len(f))
    total = np.bincount(idx, weights=v.ravel(), minlength=len(f))
    ok = cnt > 0
    return np.interp(f, f[ok], total[ok] / cnt[ok])


@_one_blas_thread
def mismatch_share(sweep: np.ndarray, truth: np.ndarray, bank: IPSFBank, *,
                   mask: np.ndarray, depth: float | str | None = None,
                   center: tuple[float, float] | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    r"""The share of a render's spectrum that its bank's blur of the truth does not
    explain, ring by ring: a bank's *mismatch profile*, measured where the truth is
    known (a rendered scene), for :func:`model_nsr`'s ``mismatch``.

    Over the mirror's image (through :func:`spectrum_window`), with :math:`P(f)` the
    noise-free sweep's ring periodogram, :math:`T(f)` the truth's and
    :math:`\bar H^2(f)` the traced kernels' mean transfer
    (:func:`kernel_shares`, ``stand_ins=False``):
    :math:`u(f) = \mathrm{clip}((P - \bar H^2 T)/P, 0, 1)`. It holds everything the
    model leaves out (the render's Monte Carlo noise, the kernels' sampling, depth and
    field, occlusion), and is correlated with the image: it scales with the image's own
    spectrum, so a share measured on one scene of a setup carries to another
    (docs/guide/weights.md measures it held out).

    Parameters
    ----------
    sweep : (H, W) or (H, W, C) ndarray
        A noise-free sweep render (linear values).
    truth : ndarray
        Its sharp image (the pinhole render), the shape of ``sweep``, same units.
    bank : IPSFBank
        The bank the restorations use.
    mask : (H, W) bool ndarray
        The mirror's image.
    depth : float, "mean" or None
        The bank depth, as in :func:`~mitsweep.deconv.kernels.select_depth` (default
        500 mm).
    center : (float, float), optional
        The pole (row, col), px, of a radial bank (default the optical axis).

    Returns
    -------
    f, share : (n,) ndarray
        The rings' mean frequencies (cycles/px) and the unexplained share, in [0, 1].
    """
    y = np.asarray(sweep, dtype=np.float64)
    x = np.asarray(truth, dtype=np.float64)
    if y.shape != x.shape:
        raise ValueError(f"sweep and truth must have one shape, got {y.shape} and {x.shape}")
    window = spectrum_window(_mask(y, mask))
    f, P = ring_spectrum(y, window=window)
    _, T = ring_spectrum(x, window=window)
    kernels = select_depth(bank, depth).astype(np.float64)
    shares = kernel_shares(bank, y.shape, mask=mask, center=center, stand_ins=False)
    keep = shares > 0
    L = max(128, 4 * int(kernels.shape[-1]))
    H2 = ring_average(np.tensordot(shares[keep], _kernel_power(kernels[keep], L), 1), f)
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.where(P > 0, (P - H2 * T) / P, 0.0)
    return f, np.clip(share, 0.0, 1.0)


@dataclass(frozen=True)
class MismatchProfile:
    """A bank's mismatch profile, calibrated on a render with its truth
    (:func:`calibrate_mismatch`), for :func:`model_nsr`'s ``mismatch``.

    Attributes
    ----------
    f : (n,) ndarray
        Ring frequencies, cycles/px.
    share : (n,) ndarray
        The unexplained share of the render's spectrum (:func:`mismatch_share`).
    scale : float
        How much of it acts on the restoration as noise: the factor on ``share`` with
        which :func:`model_nsr` chooses the calibration render's oracle NSR (below 1
        where part of what the model leaves unexplained is signal, a blur weaker than
        the bank's mean).
    oracle_nsr : float
        That oracle NSR.
    """

    f: np.ndarray
    share: np.ndarray
    scale: float
    oracle_nsr: float

    def scaled(self) -> tuple[np.ndarray, np.ndarray]:
        """``(f, min(scale · share, 1))``: the share that counts as noise."""
        return self.f, np.clip(self.scale * np.asarray(self.share), 0.0, 1.0)

    def to_dict(self) -> dict:
        """JSON-ready (lists and floats), for :meth:`from_dict`."""
        return {"f": np.asarray(self.f).tolist(), "share": np.asarray(self.share).tolist(),
                "scale": float(self.scale), "oracle_nsr": float(self.oracle_nsr)}

    def write(self, path: str | os.PathLike) -> None:
        """Write :meth:`to_dict` as JSON (atomically: a reader never sees half a file).

        Parameters
        ----------
        path : path-like
            The JSON file.
        """
        from ..io import write_text_atomic

        write_text_atomic(Path(path), json.dumps(self.to_dict(), indent=1) + "\n")

    @classmethod
    def read(cls, path: str | os.PathLike) -> MismatchProfile:
        """The profile :meth:`write` wrote (a dataset's ``calibration/mismatch.json``).

        Parameters
        ----------
        path : path-like
            The JSON file.

        Returns
        -------
        MismatchProfile
            Checked: ``f`` increasing, ``share`` in [0, 1] of its length, ``scale`` and
            ``oracle_nsr`` finite and > 0.

        Raises
        ------
        ValueError
            Not JSON, or not such a profile (naming the file and what is wrong).
        OSError
            The file cannot be read.
        """
        data = Path(path).read_bytes()
        try:
            profile = cls.from_dict(json.loads(data.decode("utf-8")))
        except (ValueError, KeyError, TypeError) as exc:
            raise ValueError(f"{path}: not a mismatch profile ({type(exc).__name__}: "
                             f"{exc})") from None
        f, share = profile.f, profile.share
        if f.ndim != 1 or f.shape != share.shape or len(f) < 2 \
                or not np.all(np.isfinite(f)) or np.any(np.diff(f) <= 0) \
                or not np.all((share >= 0) & (share <= 1)) \
                or not all(math.isfinite(v) and v > 0
                           for v in (profile.scale, profile.oracle_nsr)):
            raise ValueError(f"{path}: not a mismatch profile (f increasing, share in "
                             f"[0, 1] of its length, scale and oracle_nsr finite and > 0)")
        return profile

    @classmethod
    def from_dict(cls, d: dict) -> MismatchProfile:
        """The profile of :meth:`to_dict`'s output.

        Parameters
        ----------
        d : dict
            With ``f``, ``share``, ``scale`` and ``oracle_nsr``.
        """
        return cls(np.asarray(d["f"], dtype=np.float64),
                   np.asarray(d["share"], dtype=np.float64), float(d["scale"]),
                   float(d["oracle_nsr"]))


def calibrate_mismatch(sweep: np.ndarray, truth: np.ndarray, bank: IPSFBank, *,
                       mask: np.ndarray,
                       restore: Callable[[np.ndarray, float], np.ndarray] | None = None,
                       depth: float | str | None = None,
                       center: tuple[float, float] | None = None) -> MismatchProfile:
    """Calibrate the weight rule on a render whose truth is known: the bank's
    :func:`mismatch_share` on the noise-free ``sweep``, and the factor on it (within
    :data:`MISMATCH_SCALE_RANGE`) with which :func:`model_nsr` chooses that render's
    oracle NSR (the best by search against
    ``truth``, :func:`mitsweep.deconv.budget.oracle_weight`). Measured once per rig
    (setup and bank) on a rendered scene, it sets the weight of its other images:
    docs/guide/weights.md measures it held out (another scene, every light level).

    Parameters
    ----------
    sweep : (H, W) or (H, W, C) ndarray
        A noise-free sweep render, linear values.
    truth : ndarray
        Its sharp image (pinhole render), the shape of ``sweep``, same units.
    bank : IPSFBank
        The bank the restorations use.
    mask : (H, W) bool ndarray
        The mirror's image (the error is scored there).
    restore : callable, optional
        ``restore(image, nsr) -> restored``: the restoration the weight is for (default
        Wiener with the natural prior and ``bank``,
        :func:`mitsweep.deconv.restore.deconvolve`).
    depth, center
        As :func:`mismatch_share`.
    """
    from .budget import oracle_weight
    from .restore import deconvolve

    y = np.asarray(sweep, dtype=np.float32)
    if restore is None:
        def restore(im: np.ndarray, w: float) -> np.ndarray:
            return deconvolve(im, bank, method="wiener", weight=w, prior="natural")
    f, share = mismatch_share(y, truth, bank, mask=mask, depth=depth, center=center)
    oracle, _, _ = oracle_weight(y, np.asarray(truth, dtype=np.float64), restore,
                                 mask=np.asarray(mask, bool))

    from scipy.optimize import brentq

    def excess(log_scale: float) -> float:
        """log(chosen NSR / oracle NSR): it grows with the scale."""
        u = np.clip(math.exp(log_scale) * share, 0.0, 1.0)
        return math.log(model_nsr(y, bank, None, mask=mask, depth=depth, center=center,
                                  mismatch=(f, u)) / oracle)

    lo, hi = (math.log(b) for b in MISMATCH_SCALE_RANGE)
    if excess(lo) >= 0:
        t = lo
    elif excess(hi) <= 0:
        t = hi
    else:   # to 1 % in the scale, as the NSR search itself
        t = float(brentq(excess, lo, hi, xtol=0.01))
    scale = math.exp(t)
    logger.info("mismatch profile: oracle NSR %.3g, scale %.3g", oracle, scale)
    return MismatchProfile(f=f, share=share, scale=scale, oracle_nsr=float(oracle))


#: The scales :func:`calibrate_mismatch` searches (where no scale in it gives the oracle
#: NSR, the nearer end).
MISMATCH_SCALE_RANGE = (1e-3, 1e3)


def _kernel_power(kernels: np.ndarray, L: int) -> np.ndarray:
    """(n, L, L) |K|² of unit-sum kernels on an L × L frequency grid."""
    K = kernels.shape[-1]
    big = np.zeros((len(kernels), L, L))
    s = kernels.sum(axis=(-2, -1), keepdims=True)
    big[:, :kernels.shape[-2], :K] = kernels / s
    return np.abs(sfft.fft2(big, axes=(-2, -1), workers=-1)) ** 2


@renamed_keywords(depth_mm="depth")
@_one_blas_thread
def wiener_risk(image: np.ndarray, bank: IPSFBank, noise_var: float, *,
                floor_var: float | None = None, mask: np.ndarray | None = None,
                depth: float | str | None = None,
                center: tuple[float, float] | None = None, n_px: float | None = None,
                bounds: tuple[float, float] = (1e-10, MAX_NSR),
                window: np.ndarray | None = None,
                unexplained_share: tuple[np.ndarray, np.ndarray] | None = None
                ) -> tuple[float, Callable[[float], float]]:
    r"""The natural-prior NSR of least expected error for ``image`` with noise
    variance ``noise_var`` (its units²), and the risk function (module docstring).

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
        The image to restore (linear values).
    bank : IPSFBank
        The image's bank; its kernels at ``depth`` (default 500 mm), weighted by
        :func:`kernel_shares` over ``mask`` (the pixels restored; default all).
    noise_var : float
        Noise variance over the mask, image units².
    floor_var : float, optional
        The noise variance over the whole frame, subtracted from its periodogram
        (default ``noise_var``).
    mask : (H, W) bool ndarray, optional
        The pixels restored (default all).
    depth : float, "mean" or None
        The bank depth, as in :func:`~mitsweep.deconv.kernels.select_depth` (default
        500 mm).
    center : (float, float), optional
        The pole (row, col), px, of a radial bank (default the optical axis).
    n_px : float, optional
        The deconvolver's size for the prior's scale (default √(HW)).
    bounds : (float, float)
        Search range of the NSR.
    window : (H, W) ndarray, optional
        The taper the spectrum is read through (:func:`ring_spectrum`; default the
        whole frame). ``floor_var`` is then the noise under it.
    unexplained_share : (f, share), optional
        A mismatch profile (:func:`mismatch_share`): that share of the periodogram above
        the noise floor counts as error the restoration passes on, like noise but with
        the image's own spectrum, not as signal; the rest is the blurred signal.
        Default none: only ``noise_var``.

    Returns
    -------
    nsr, risk
        The NSR (a grid of 45 in log NSR, then a bounded Brent search to 1 % between
        the best one's neighbours) and ``risk(nsr) -> float``, the expected MSE per
        pixel of that NSR's restoration (image units²).
    """
    from scipy.optimize import minimize_scalar

    img = np.asarray(image, dtype=np.float64)
    kernels = select_depth(bank, depth).astype(np.float64)
    shares = kernel_shares(bank, img.shape, mask=mask, center=center)
    keep = shares > 0
    L = max(128, 4 * int(kernels.shape[-1]))
    H2 = _kernel_power(kernels[keep], L)
    w = shares[keep]
    Hbar = np.tensordot(w, H2, 1)
    fq = sfft.fftfreq(L)
    fr = np.hypot(fq[:, None], fq[None, :])
    f_ring, p_ring = ring_spectrum(img, window=window)
    var = float(noise_var)
    floor = var if floor_var is None else float(floor_var)
    above = np.maximum(np.interp(fr, f_ring, p_ring) - floor, 0.0)
    err: float | np.ndarray = var
    if unexplained_share is not None:
        uf, us = (np.asarray(a, dtype=np.float64) for a in unexplained_share)
        u = np.clip(np.interp(fr, uf, us), 0.0, 1.0)
        err = var + u * above
        above = (1.0 - u) * above
    S = above / np.maximum(Hbar, 1e-12)
    n = float(np.sqrt(img.shape[0] * img.shape[1])) if n_px is None else float(n_px)
    c = natural_prior_scale(n) * fr * fr

    def risk_log(t: float) -> float:
        R = math.exp(t) * c
        den = H2 + R
        e = (R * R * S + H2 * err) / (den * den)
        return float(np.dot(w, e.mean(axis=(1, 2))))

    lo, hi = (math.log(float(b)) for b in bounds)
    grid = np.linspace(lo, hi, 45)
    vals = [risk_log(t) for t in grid]
    i = int(np.argmin(vals))
    res = minimize_scalar(risk_log, bounds=(grid[max(i - 1, 0)], grid[min(i + 1, 44)]),
                          method="bounded", options={"xatol": 0.01})
    t = float(res.x) if res.fun <= vals[i] else float(grid[i])
    return math.exp(t), (lambda nsr: risk_log(math.log(float(nsr))))


@renamed_keywords(depth_mm="depth")
@_one_blas_thread
def unexplained_variance(image: np.ndarray, bank: IPSFBank, *,
                         mask: np.ndarray | None = None, depth: float | str | None = None,
                         center: tuple[float, float] | None = None,
                         n_px: float | None = None, window: np.ndarray | None = None,
                         stand_ins: bool = True) -> float:
    r"""The variance of what the bank's blur and the natural prior leave unexplained in
    ``image``: generalised cross-validation (Golub, Heath & Wahba 1979) on the ring
    spectrum with the bank's mean transfer :math:`\bar H^2` (as :func:`wiener_risk`),
    :math:`\hat\sigma^2 = \sum P r^2 / \sum r`, :math:`r = \nu c/(\bar H^2 + \nu c)` at
    the GCV-best ν (Wahba 1983).

    A noise model holds the sensor's noise only; a render's Monte Carlo noise and the
    bank's mismatch with the image (kernel sampling, depth, occlusion) act on a Wiener
    filter as more noise, and this measures them with it. See
    :func:`mitsweep.deconv.regularization.gcv_noise` for the same rule with one kernel.

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
        The image (linear values).
    bank : IPSFBank
        Its bank; the kernels weighted by :func:`kernel_shares` over ``mask``.
    mask : (H, W) bool ndarray, optional
        The pixels restored (default all).
    depth : float, "mean" or None
        The bank depth, as in :func:`~mitsweep.deconv.kernels.select_depth` (default
        500 mm).
    center : (float, float), optional
        The pole (row, col), px, of a radial bank (default the optical axis).
    n_px : float, optional
        The deconvolver's size for the prior's scale (default √(HW)).
    window : (H, W) ndarray, optional
        The taper the spectrum is read through (:func:`ring_spectrum`; default the
        whole frame).
    stand_ins : bool
        As :func:`kernel_shares`: False models the image with the traced kernels only
        (a grid bank's delta stand-ins are the deconvolution's, not the image's blur).

    Returns
    -------
    float
        σ², image units².
    """
    from scipy.optimize import minimize_scalar

    img = np.asarray(image, dtype=np.float64)
    kernels = select_depth(bank, depth).astype(np.float64)
    shares = kernel_shares(bank, img.shape, mask=mask, center=center, stand_ins=stand_ins)
    keep = shares > 0
    L = max(128, 4 * int(kernels.shape[-1]))
    Hbar = np.tensordot(shares[keep], _kernel_power(kernels[keep], L), 1)
    fq = sfft.fftfreq(L)
    fr = np.hypot(fq[:, None], fq[None, :])
    f_ring, p_ring = ring_spectrum(img, window=window)
    n = float(np.sqrt(img.shape[0] * img.shape[1])) if n_px is None else float(n_px)
    c = natural_prior_scale(n) * fr * fr
    ok = c > 0
    P, Hb, c = np.interp(fr, f_ring, p_ring)[ok], Hbar[ok], c[ok]

    def terms(t: float) -> tuple[float, float]:
        R = math.exp(t) * c
        r = R / (Hb + R)
        return float(np.dot(P, r * r)), float(np.sum(r))

    def V(t: float) -> float:
        rss, tr = terms(t)
        return rss / max(tr, 1e-300) ** 2

    grid = np.linspace(math.log(1e-10), math.log(MAX_NSR), 64)
    i = int(np.argmin([V(t) for t in grid]))
    res = minimize_scalar(V, bounds=(grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]),
                          method="bounded", options={"xatol": 0.01})
    rss, tr = terms(float(res.x))
    return rss / max(tr, 1e-300)


def high_frequency_floor(image: np.ndarray, *, band: float = 0.45) -> float:
    """The mean periodogram of the rings beyond ``band`` cycles/pixel (the corners of
    the spectrum): noise plus what the blur leaves there, an upper bound of σ².

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
        The image.
    band : float
        Lowest frequency counted, cycles/px (default 0.45; with no ring beyond it, the
        highest ring).
    """
    f, p = ring_spectrum(image)
    sel = f >= band
    return float(np.mean(p[sel])) if sel.any() else float(p[-1])


@renamed_keywords(depth_mm="depth")
@_one_blas_thread
def model_nsr(image: np.ndarray, bank: IPSFBank,
              noise: SensorNoise | float | None = None, *, mask: np.ndarray | None = None,
              level: float = 1.0, extra_variance: float = 0.0,
              depth: float | str | None = None,
              center: tuple[float, float] | None = None, n_px: float | None = None,
              unexplained: bool = True, details: dict | None = None,
              spectrum: str = "frame",
              mismatch: MismatchProfile | tuple[np.ndarray, np.ndarray] | None = None
              ) -> float:
    r"""Wiener's natural-prior NSR for ``image`` from its noise and its own spectrum.

    The NSR of least expected error (:func:`wiener_risk`) with the noise variance of
    :func:`noise_variance` (``noise``: the sensor model, whose relative exposure 1.0 is
    ``level`` in the image's units; a σ; or None: estimated, see :func:`blind_nsr`)
    plus ``extra_variance``: white noise the model does not hold (a render's Monte
    Carlo noise), image units². The noise is taken over ``mask`` (the pixels restored)
    for the error, and over the whole frame for the periodogram's floor (dark pixels
    outside a mirror's image carry read noise only).

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
        The image to restore (linear values).
    bank : IPSFBank
        Its bank.
    noise, level, mask
        As :func:`noise_variance`.
    n_px : float, optional
        The deconvolver's image size for the prior's scale (default √(HW), as
        :func:`~mitsweep.deconv.polar.polar_deconvolve` and
        :func:`~mitsweep.deconv.spatial.spatially_varying_deconvolve` use).
    details : dict, optional
        Filled with ``noise_variance`` (over the mask), ``frame_noise_variance`` and
        ``expected_mse`` (the risk at the NSR chosen).
    spectrum : {"frame", "mirror"}
        Where the spectrum is read. ``"frame"`` (default; the datasets' rule,
        ``weights="model"``): the whole frame, with every kernel the restoration
        applies. ``"mirror"``: through a taper over ``mask`` (:func:`spectrum_window`),
        the pixels restored, with the unexplained variance modelled by the traced
        kernels only (``stand_ins=False``): outside a mirror's image lies content the
        bank does not describe. Measured against the oracle in
        docs/guide/weights.md; not the default yet (it loses more on the 256-px tilted
        paraboloid). Without a mask, or with one that selects every pixel, the two
        agree.
    mismatch : MismatchProfile or (f, share), optional
        The bank's mismatch profile, calibrated on another render of the setup with its
        truth (:func:`calibrate_mismatch`; its :meth:`~MismatchProfile.scaled` share),
        or a share as is (:func:`mismatch_share`): what the model leaves unexplained is
        then that share of the image's own spectrum (colored, as a render's mismatch
        is) instead of white noise of the cross-validated variance; the spectrum is read
        over the mirror (``spectrum`` is ignored; ``mask`` is required) and the noise
        is the model's (``noise``) plus ``extra_variance``. With ``noise`` None the
        image is taken to be as noisy as the render the profile was measured on (whose
        Monte Carlo noise the profile holds): give a photo's sensor noise as a model
        or a σ. Measured against the oracle, held out, in
        docs/guide/weights.md.

    Returns
    -------
    float
        The NSR, in [1e-10, :data:`~mitsweep.deconv.wiener.MAX_NSR`].
    """
    if spectrum not in ("mirror", "frame"):
        raise ValueError(f"spectrum must be 'mirror' or 'frame', got {spectrum!r}")
    img = np.asarray(image)
    m = _mask(img, mask)
    if mismatch is not None:
        return _profiled_nsr(img, bank, noise, m, mismatch, level=level,
                             extra_variance=extra_variance, depth=depth, center=center,
                             n_px=n_px, details=details)
    mirror = spectrum == "mirror" and mask is not None and not m.all()
    window = spectrum_window(m) if mirror else None
    # what the model does not hold, measured on the image: white noise (wavelet and
    # periodogram floor) and everything blur + prior leave unexplained (GCV)
    blind = 0.0 if not unexplained and noise is not None else max(
        blind_noise_variance(img),
        unexplained_variance(img, bank, mask=m, depth=depth, center=center, n_px=n_px,
                             window=window, stand_ins=not mirror))
    if noise is None:
        var = frame = blind + float(extra_variance)
    else:
        var = max(noise_variance(img, noise, mask=m, level=level) + float(extra_variance),
                  blind)
        frame = var if mirror else max(
            noise_variance(img, noise, level=level) + float(extra_variance), blind)
    nsr, risk = wiener_risk(img, bank, var, floor_var=frame, mask=mask, depth=depth,
                            center=center, n_px=n_px, window=window)
    if details is not None:
        details.update(noise_variance=var, frame_noise_variance=frame,
                       expected_mse=risk(nsr))
    logger.info("model NSR %.3g (noise variance %.3g)", nsr, var)
    return nsr


def _profiled_nsr(img: np.ndarray, bank: IPSFBank, noise: SensorNoise | float | None,
                  m: np.ndarray,
                  mismatch: MismatchProfile | tuple[np.ndarray, np.ndarray], *,
                  level: float, extra_variance: float, depth: float | str | None,
                  center: tuple[float, float] | None, n_px: float | None,
                  details: dict | None) -> float:
    """:func:`model_nsr` with a mismatch profile (its ``mismatch``)."""
    pair = mismatch.scaled() if isinstance(mismatch, MismatchProfile) else mismatch
    f, share = (np.asarray(a, dtype=np.float64) for a in pair)
    if f.ndim != 1 or f.shape != share.shape or len(f) < 2 or not (
            np.all(np.isfinite(f)) and np.all(np.isfinite(share))) \
            or np.any(np.diff(f) <= 0):
        raise ValueError("mismatch must be (f, share): two finite 1-D arrays of one length "
                         "(at least 2), f increasing (mismatch_share gives them)")
    if m.all():
        raise ValueError("mismatch needs the mirror's mask: the profile is read over it")
    # noise None: as noisy as the render the profile was measured on (its Monte Carlo
    # noise is in the profile); a blind estimate would count that noise twice
    var = (0.0 if noise is None
           else noise_variance(img, noise, mask=m, level=level)) + float(extra_variance)
    nsr, risk = wiener_risk(img, bank, var, mask=m, depth=depth, center=center, n_px=n_px,
                            window=spectrum_window(m), unexplained_share=(f, share))
    if details is not None:
        details.update(noise_variance=var, frame_noise_variance=var, expected_mse=risk(nsr))
    logger.info("model NSR %.3g with a mismatch profile (noise variance %.3g)", nsr, var)
    return nsr


def blind_noise_variance(image: np.ndarray) -> float:
    """σ² of an image with no noise model: the wavelet estimate
    (:func:`~mitsweep.deconv.wiener.estimate_noise_sigma`), at most the periodogram's
    floor (:func:`high_frequency_floor`): at low noise the finest wavelet band also
    holds the sharpest detail (0.0019 read for σ = 0.001 on the bench mosaic).

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
        The image.
    """
    return min(float(estimate_noise_sigma(image)) ** 2, high_frequency_floor(image))


@renamed_keywords(depth_mm="depth")
@_one_blas_thread
def blind_nsr(image: np.ndarray, bank: IPSFBank, *, mask: np.ndarray | None = None,
              depth: float | str | None = None,
              center: tuple[float, float] | None = None, n_px: float | None = None) -> float:
    """:func:`model_nsr` with nothing known (σ² by :func:`blind_noise_variance`), at
    least :data:`~mitsweep.deconv.wiener.DEFAULT_NSR_FLOOR` (a noiseless render still
    carries ~1e-4 relative error).

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
        The image to restore (linear values).
    bank : IPSFBank
        Its bank.
    mask : (H, W) bool ndarray, optional
        The pixels restored (default all).
    depth : float, "mean" or None
        The bank depth, as in :func:`~mitsweep.deconv.kernels.select_depth` (default
        500 mm).
    center : (float, float), optional
        The pole (row, col), px, of a radial bank (default the optical axis).
    n_px : float, optional
        The deconvolver's size for the prior's scale (default √(HW)).
    """
    nsr = model_nsr(image, bank, None, mask=mask, depth=depth, center=center, n_px=n_px)
    return max(nsr, DEFAULT_NSR_FLOOR)
