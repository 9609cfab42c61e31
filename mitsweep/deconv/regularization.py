r"""Regularisation chosen from the noise model and the image, not guessed.

- :func:`noise_sigma`: the noise standard deviation of an image, from a
  :class:`~mitsweep.deconv.noise.SensorNoise` model, a given number, or the image
  itself (Donoho's wavelet estimate, :func:`~mitsweep.deconv.wiener.estimate_noise_sigma`).
- :func:`discrepancy_nsr`: the Wiener NSR (natural-image prior) by Morozov's
  discrepancy principle [1]_: the NSR at which the restoration explains the data to the
  noise, :math:`\lVert A\hat x - y\rVert^2 = \tau N \sigma^2`. The residual of a
  Wiener filter is analytic in the Fourier domain, so the search costs one FFT of the
  image; the spatially varying blur is stood in for by the bank's IPSF at the radius
  that halves the restored disk's area (the residual is a global sum).
- :func:`gcv_noise`: the NSR by generalised cross-validation [3]_ [4]_ and the σ it implies,
  with no noise model: the level of everything the blur and the prior leave
  unexplained (heavy-tailed Monte Carlo noise, which the wavelet estimate's median
  sees only the core of, a bank that does not fit the image). The prior-based solvers
  take the largest of this, the given or estimated σ, and the discrepancy's leftover.
- :func:`prior_weight`: the weight λ of a gradient prior [2]_ :math:`\lambda \sum |\nabla x|^\alpha`
  as the MAP weight of a generalised-Gaussian gradient law fitted to a first estimate,
  :math:`\lambda = \kappa_\alpha\, \sigma^2 / (\alpha\, \overline{|\nabla x_0|^\alpha})`,
  with one constant :math:`\kappa_\alpha` per prior (:data:`PRIOR_WEIGHT_SCALE`).

The constants were tuned on one set of images, blurs and noise levels and checked on
others (``tests/test_deconv_solvers.py``).

References
----------
.. [1] V. A. Morozov, "On the solution of functional equations by the method of
   regularization", Soviet Math. Dokl. 7, 414–417, 1966.
.. [2] D. Krishnan and R. Fergus, "Fast image deconvolution using hyper-Laplacian
   priors", NIPS 2009.
.. [3] G. H. Golub, M. Heath and G. Wahba, "Generalized cross-validation as a method
   for choosing a good ridge parameter", Technometrics 21, 215–223, 1979.
.. [4] G. Wahba, "Bayesian 'confidence intervals' for the cross-validated smoothing
   spline", J. R. Stat. Soc. B 45, 133–150, 1983.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.fft as sfft

from ..deprecation import renamed_keywords
from ..io.bank import BankError, IPSFBank
from .noise import SensorNoise
from .kernels import interpolate_radial, radii_px, select_depth
from .wiener import (DEFAULT_NSR_FLOOR, MAX_NSR, estimate_noise_sigma, estimate_nsr,
                     fast_shape, kernel_spectrum, natural_prior_scale)

__all__ = ["noise_sigma", "discrepancy_nsr", "calibrated_nsr", "surrogate_kernel",
           "prior_weight", "PRIOR_WEIGHT_SCALE", "DISCREPANCY_TAU", "discrepancy", "gcv_noise"]

logger = logging.getLogger(__name__)

#: κ_α of :func:`prior_weight`, per prior exponent α, tuned on the bench mosaic only
#: (synthetic cross IPSF). The PSNR-best κ for TV was 1 at 512 px with the 50-lux noise
#: (κ = 0.5, 1, 2: 31.58, 31.84, 31.63 dB) and at 1024 px, but 0.25-0.5 at 256 px with
#: white noise σ = 0.003, 0.01, 0.03 (κ = 0.5 within 0.05, 0, 0.5 dB of the best, κ = 1
#: 0.4, 0.5, 1.5 dB below); κ = 0.5 keeps the worst loss over these cases at about
#: 0.5 dB (α = 2/3 behaved alike). Checked on other photographs and a wider blur in
#: tests/test_deconv_solvers.py.
PRIOR_WEIGHT_SCALE = {1.0: 0.5, 2.0 / 3.0: 0.5}

#: τ of the discrepancy principle: the residual's power per pixel over σ² (Morozov's
#: τ ≥ 1; 1 is the noise exactly).
DISCREPANCY_TAU = 1.0


def noise_sigma(image: np.ndarray, noise: SensorNoise | float | None = None) -> float:
    """Noise standard deviation of ``image`` (its units).

    Parameters
    ----------
    image : (H, W[, C]) ndarray
    noise : SensorNoise, float or None
        A sensor model (the image in its relative-exposure units: σ² is its variance at
        the image's mean level), a σ, or None to estimate σ from the image.

    Returns
    -------
    float
        σ, at least 1 % of the image's standard deviation (as
        :data:`~mitsweep.deconv.wiener.DEFAULT_NSR_FLOOR`: a noiseless render still
        carries ~1e-4 relative error, and a zero σ would leave spectral zeros
        unregularised), and at least ``1e-6 (1 + max |image|)``.
    """
    img = np.asarray(image, dtype=np.float64)
    floor = float(np.sqrt(DEFAULT_NSR_FLOOR)) * float(np.std(img))
    if noise is None:
        s = estimate_noise_sigma(img)
    elif isinstance(noise, (int, float, np.floating, np.integer)):
        s = float(noise)
        if not (np.isfinite(s) and s >= 0):
            raise ValueError(f"noise sigma must be a finite number >= 0, got {noise!r}")
    elif hasattr(noise, "variance"):
        s = float(np.sqrt(noise.variance(max(float(np.mean(img)), 0.0))))
    else:
        raise ValueError(f"noise must be a SensorNoise, a sigma or None, got {noise!r}")
    # and never exactly 0: a constant image would otherwise get no regularisation,
    # which a kernel's spectral zeros turn into a division by zero
    return max(s, floor, 1e-6 * (1.0 + float(np.max(np.abs(img), initial=0.0))))


def _residual_spectrum(image, psf, mask):
    """(|Y|² with Parseval weights, |H|², natural-prior |f|² scale, pixel count, weights
    of the rfft2 half plane) of the mean-removed image; None for an empty mask."""
    img = np.asarray(image, dtype=np.float64)
    if img.ndim == 3:
        img = img.mean(axis=2)
    vals = img[mask] if mask is not None else img.ravel()
    n = float(vals.size)
    if n == 0:
        return None
    x = img - float(vals.mean())
    if mask is not None:
        x = np.where(mask, x, 0.0)
    H_, W_ = x.shape
    M, N = fast_shape((H_, W_), (0, 0))
    Y2 = np.abs(sfft.rfft2(x, s=(M, N), workers=-1)) ** 2
    # rfft2 half plane: interior columns stand for two coefficients
    wcol = np.full(N // 2 + 1, 2.0)
    wcol[0] = 1.0
    if N % 2 == 0:
        wcol[-1] = 1.0
    Y2 *= wcol[None, :] / (M * N)
    Hk = np.abs(kernel_spectrum(psf, (M, N))) ** 2
    fy = sfft.fftfreq(M)[:, None]
    fx = sfft.rfftfreq(N)[None, :]
    c = natural_prior_scale(float(np.sqrt(n))) * (fy * fy + fx * fx)
    return Y2, Hk, c, n, np.broadcast_to(wcol[None, :] * (n / (M * N)), Y2.shape)


def gcv_noise(image: np.ndarray, psf: np.ndarray, *,
              mask: np.ndarray | None = None) -> tuple[float, float]:
    r"""Wiener NSR by generalised cross-validation, and the noise σ it implies.

    GCV (Golub, Heath and Wahba) needs no σ: it minimises
    :math:`V(\nu) = \frac{1}{N}\lVert (I - A G_\nu) y\rVert^2 /
    \left(\frac{1}{N}\operatorname{tr}(I - A G_\nu)\right)^2`
    over the natural-prior NSR ν, with :math:`I - A G_\nu` diagonal in the Fourier
    domain, :math:`R/(|H|^2 + R)`. The noise variance then follows as
    :math:`\hat\sigma^2 = \lVert (I - A G)y\rVert^2 / \operatorname{tr}(I - A G)`
    (Wahba 1983): everything the blur and the prior do not explain counts, Monte
    Carlo noise and a kernel that does not quite fit included.

    Returns ``(nsr, sigma)``; NSR in [DEFAULT_NSR_FLOOR, MAX_NSR].

    Parameters
    ----------
    image : (H, W) ndarray
        The blurred image.
    psf : (K0, K1) ndarray
        The shift-invariant kernel standing for the blur (:func:`surrogate_kernel`).
    mask : (H, W) bool ndarray, optional
        Region that counts (the mirror's disk); outside, the image is set to its mean
        there (default the whole image).
    """
    return _gcv(_residual_spectrum(image, psf, mask))


def _gcv(spec) -> tuple[float, float]:
    if spec is None:
        return float(DEFAULT_NSR_FLOOR), 0.0
    Y2, Hk, c, n, wt = spec
    ok = c > 0                              # the DC term: R = 0, r = 0
    # float32 terms: ~35 evaluations cost less than the FFT before them (a regular
    # subsample of the spectrum instead moved σ by 16 % on a 2048² mosaic)
    a = (Hk[ok] / c[ok]).astype(np.float32)  # r = R / (|H|² + R) = ν / (a + ν)
    Y2, wt = Y2[ok].astype(np.float32), wt[ok].astype(np.float32)

    def terms(log_nsr):
        nu = np.float32(np.exp(log_nsr))
        r = a + nu
        np.divide(nu, r, out=r)
        return float(np.dot(Y2, r * r)), float(np.dot(wt, r))

    def V(log_nsr):
        rss, tr = terms(log_nsr)
        return rss * n / max(tr, 1e-300) ** 2

    lo, hi = np.log(DEFAULT_NSR_FLOOR), np.log(MAX_NSR)
    grid = np.linspace(lo, hi, 17)
    i = int(np.argmin([V(g) for g in grid]))
    a_, b_ = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    for _ in range(16):                     # golden section on the bracket
        m1, m2 = b_ - 0.618 * (b_ - a_), a_ + 0.618 * (b_ - a_)
        if V(m1) < V(m2):
            b_ = m2
        else:
            a_ = m1
    log_nsr = 0.5 * (a_ + b_)
    rss, tr = terms(log_nsr)
    sigma = float(np.sqrt(rss / max(tr, 1e-300)))
    logger.info("GCV NSR %.3g, sigma %.3g", float(np.exp(log_nsr)), sigma)
    return float(np.exp(log_nsr)), sigma


def discrepancy_nsr(image: np.ndarray, psf: np.ndarray, sigma: float, *,
                    tau: float = DISCREPANCY_TAU, mask: np.ndarray | None = None) -> float:
    r"""Natural-prior Wiener NSR whose residual power equals ``tau · σ²`` per pixel.

    See :func:`discrepancy`, which also returns the residual's level.

    Parameters
    ----------
    image : (H, W) ndarray
        The blurred image.
    psf : (K0, K1) ndarray
        The shift-invariant kernel standing for the blur (:func:`surrogate_kernel`).
    sigma : float
        Noise standard deviation, in the image's units.
    tau : float
        Residual power per pixel over σ² (default :data:`DISCREPANCY_TAU`, 1).
    mask : (H, W) bool ndarray, optional
        Region that counts (the mirror's disk); outside, the image is set to its mean
        there (default the whole image).
    """
    return discrepancy(image, psf, sigma, tau=tau, mask=mask)[0]


def discrepancy(image: np.ndarray, psf: np.ndarray, sigma: float, *,
                tau: float = DISCREPANCY_TAU,
                mask: np.ndarray | None = None) -> tuple[float, float]:
    r"""Natural-prior Wiener NSR whose residual power equals ``tau · σ²`` per pixel.

    The residual of the Wiener estimate with kernel spectrum H and regulariser
    :math:`R = \text{nsr}\cdot c\,|f|^2` is :math:`(1 - H G) Y = R/(|H|^2 + R)\, Y`;
    its power is increasing in the NSR, so a bisection on log NSR finds the one that
    matches :math:`\tau N \sigma^2` (Parseval). ``mask`` restricts the image's mean
    removal and the pixel count to a region (the mirror disk); outside, the image is
    set to its mean there.

    Returns ``(nsr, residual_sigma)``: the NSR clamped to [DEFAULT_NSR_FLOOR, MAX_NSR]
    and the rms residual it leaves (σ √τ when the principle is met). When even the
    smallest NSR leaves more residual than the noise, the principle has no solution;
    the image's own estimate (:func:`~mitsweep.deconv.wiener.estimate_nsr`) is
    returned with its residual, larger than σ: the level of what the model does not
    explain, which the prior-based solvers then take as the noise.

    Parameters
    ----------
    image : (H, W) ndarray
        The blurred image.
    psf : (K0, K1) ndarray
        The shift-invariant kernel standing for the blur (:func:`surrogate_kernel`).
    sigma : float
        Noise standard deviation, in the image's units (<= 0: the NSR floor).
    tau : float
        Residual power per pixel over σ² (default :data:`DISCREPANCY_TAU`, 1).
    mask : (H, W) bool ndarray, optional
        Region that counts (the mirror's disk); outside, the image is set to its mean
        there (default the whole image).
    """
    return _discrepancy(_residual_spectrum(image, psf, mask), sigma, tau, image, mask)


def _discrepancy(spec, sigma, tau, image, mask) -> tuple[float, float]:
    if spec is None or sigma <= 0:
        return float(DEFAULT_NSR_FLOOR), float(sigma)
    Y2, Hk, c, n, _ = spec
    target = tau * n * sigma * sigma

    def residual(log_nsr):
        R = np.exp(log_nsr) * c
        return float(np.sum(Y2 * (R / (Hk + R)) ** 2))

    lo, hi = np.log(DEFAULT_NSR_FLOOR), np.log(MAX_NSR)
    if residual(lo) >= target:
        # no NSR meets the principle: the image holds more than blur plus σ can explain
        # (Monte Carlo noise, a bank that does not fit, σ under-estimated). The floor
        # would be the least regularised choice, exactly wrong here (measured on a
        # rendered sphere sweep: 14.3 dB against 20.0 dB), so the image's own estimate
        # stands in
        nsr = estimate_nsr(image, mask=mask)
        logger.info("discrepancy principle has no solution (residual above the noise at "
                    "every NSR): the image's NSR estimate %.3g is used", nsr)
        return float(nsr), float(np.sqrt(residual(np.log(nsr)) / n))
    if residual(hi) <= target:
        return float(MAX_NSR), float(np.sqrt(residual(hi) / n))
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if residual(mid) < target:
            lo = mid
        else:
            hi = mid
    nsr = float(np.exp(0.5 * (lo + hi)))
    logger.info("discrepancy NSR %.3g (sigma %.3g)", nsr, sigma)
    return nsr, float(np.sqrt(tau) * sigma)


@renamed_keywords(depth_mm="depth")
def surrogate_kernel(bank: IPSFBank, image_shape: tuple[int, ...], *,
                     depth: float | str | None = None,
                     center: tuple[float, float] | None = None) -> np.ndarray:
    """The one IPSF that stands for the bank in :func:`discrepancy_nsr`.

    Radial bank: the kernel at r_max / √2, the radius that halves the restored disk's
    area (r_max the bank's largest radius plus a kernel, capped at the image's farthest
    corner, as in :func:`~mitsweep.deconv.polar.polar_deconvolve`); grid bank: the
    middle grid point's kernel.

    Parameters
    ----------
    bank : IPSFBank
        A radial or grid bank.
    image_shape : tuple of int
        The image's (H, W[, C]).
    depth : float, "mean" or None
        The bank depth, as in :func:`~mitsweep.deconv.kernels.select_depth` (default
        500 mm).
    center : (float, float), optional
        The pole (row, col), px, of a radial bank (default the optical axis).
    """
    from .polar import polar_grid

    kernels = select_depth(bank, depth)
    if bank.kind == "radial":
        rad = radii_px(bank)
        r_max = min(float(rad.max()) + kernels.shape[-1],
                    polar_grid(image_shape, center=center).r_max)
        return interpolate_radial(kernels, rad, r_max / np.sqrt(2))
    if bank.kind == "grid":
        return kernels[len(kernels) // 2]
    raise BankError(f"unknown bank kind {bank.kind!r}")


@renamed_keywords(depth_mm="depth")
def calibrated_nsr(image: np.ndarray, bank: IPSFBank, *, noise: SensorNoise | float | None = None,
                   depth: float | str | None = None,
                   center: tuple[float, float] | None = None) -> float:
    """Wiener NSR (natural prior) for ``image`` by the discrepancy principle: the median
    over channels of :func:`discrepancy_nsr` with σ from :func:`noise_sigma` and the
    bank's :func:`surrogate_kernel`.

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
        The blurred image.
    bank : IPSFBank
        The bank it will be deconvolved with.
    noise : SensorNoise, float or None
        A sensor model, a σ, or None to estimate σ from each channel
        (:func:`noise_sigma`).
    depth : float, "mean" or None
        The bank depth, as in :func:`~mitsweep.deconv.kernels.select_depth` (default
        500 mm).
    center : (float, float), optional
        The pole (row, col), px, of a radial bank (default the optical axis).
    """
    img = np.asarray(image)
    chans = [img] if img.ndim == 2 else [img[..., c] for c in range(img.shape[2])]
    k = surrogate_kernel(bank, img.shape, depth=depth, center=center)
    return float(np.median([discrepancy_nsr(c, k, noise_sigma(c, noise)) for c in chans]))


def prior_weight(gradient_moment: float, sigma: float, alpha: float) -> float:
    r"""λ of the prior :math:`\lambda \sum_p |\nabla x_p|^\alpha` (data term
    :math:`\tfrac12\lVert Ax - y\rVert^2`).

    A generalised-Gaussian gradient law :math:`p(g) \propto \exp(-|g|^\alpha / (\alpha m))`
    has :math:`E|g|^\alpha = m`, so its MAP weight is :math:`\sigma^2 / (\alpha m)`;
    ``gradient_moment`` is m measured on a first estimate, and the MAP weight is scaled
    by :data:`PRIOR_WEIGHT_SCALE` (MAP weights are not the PSNR-optimal ones).

    Parameters
    ----------
    gradient_moment : float
        m, the mean of :math:`|\nabla x|^\alpha` on a first estimate (floored at 1e-12).
    sigma : float
        Noise standard deviation, in the image's units.
    alpha : float
        The prior's exponent; one of those in :data:`PRIOR_WEIGHT_SCALE`.
    """
    key = min(PRIOR_WEIGHT_SCALE, key=lambda a: abs(a - alpha))
    if abs(key - alpha) > 1e-6:
        raise ValueError(f"no calibrated weight for prior exponent {alpha}; "
                         f"calibrated: {sorted(PRIOR_WEIGHT_SCALE)}")
    m = max(float(gradient_moment), 1e-12)
    return float(PRIOR_WEIGHT_SCALE[key] * sigma * sigma / (alpha * m))
