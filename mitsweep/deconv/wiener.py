"""Wiener deconvolution with a shift-invariant kernel, done carefully.

Compared with :func:`skimage.restoration.wiener` (see docs/design.md) this keeps the
complex transfer function whole, pads the image against circular wrap-around, uses a
stated regulariser (a constant noise-to-signal ratio, or the natural-image ``1/|f|²``
power spectrum that the V metric weighs with), picks fast FFT lengths, keeps float32 as
float32 and never clips.
"""

from __future__ import annotations

import logging
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, DTypeLike
import scipy.fft as sfft

from ..resources import check_allocation

__all__ = ["wiener_deconvolve", "wiener_filter", "kernel_spectrum", "regulariser",
           "estimate_nsr", "estimate_noise_sigma", "natural_prior_scale", "fast_shape",
           "working_dtype", "check_image_values", "check_nsr", "wiener_memory_bytes",
           "PRIORS", "DEFAULT_NSR_FLOOR", "MAX_NSR", "MAX_ABS_VALUE"]

logger = logging.getLogger(__name__)

PRIORS = ("constant", "natural")

#: Smallest NSR used when it is estimated from the image: a noiseless float render still
#: carries ~1e-4 relative error (Monte Carlo, 16-bit EXR), and 1e-4 bounds the gain of the
#: inverse filter at 1 / (2 sqrt(1e-4)) = 50.
DEFAULT_NSR_FLOOR = 1e-4
#: Largest NSR accepted: at 1e6 the filter's gain is below 1e-3 at every frequency the
#: prior regularises, so the output is the image's mean; beyond, R overflows float32.
MAX_NSR = 1e6
#: Largest ``|value|`` of an image to deconvolve. An FFT coefficient is at most the sum of
#: ``|values|`` (<= 2^31 pixels of a padded 32768² image: 2e29 at 1e20), which leaves the
#: filter's gain a factor 1e9 below float32's 3.4e38; beyond, float32 FFTs overflow.
MAX_ABS_VALUE = 1e20

#: The :func:`numpy.pad` modes (its ``mode`` argument).
PadMode = Literal["constant", "edge", "linear_ramp", "maximum", "mean", "median", "minimum",
                  "reflect", "symmetric", "wrap", "empty"]


def check_image_values(image: np.ndarray) -> None:
    """Raise ValueError if ``image`` holds NaN, inf, or values beyond :data:`MAX_ABS_VALUE`.

    Parameters
    ----------
    image : ndarray
        The image, any shape (an empty one passes).
    """
    if not np.all(np.isfinite(image)):
        raise ValueError("image holds NaN or inf values")
    peak = float(np.max(np.abs(image))) if np.size(image) else 0.0
    if peak > MAX_ABS_VALUE:
        raise ValueError(f"image values reach {peak:.3g}; deconvolution takes linear values up "
                         f"to {MAX_ABS_VALUE:g} in magnitude (float32 FFTs overflow beyond): "
                         f"rescale the image")


def check_nsr(nsr: float) -> float:
    """``nsr`` as a float in [0, :data:`MAX_NSR`]; ValueError otherwise.

    Parameters
    ----------
    nsr : float
        A noise-to-signal ratio (σ_n² / σ_s²).
    """
    x = float(nsr)
    if not (np.isfinite(x) and 0 <= x <= MAX_NSR):
        raise ValueError(f"nsr must be a number in [0, {MAX_NSR:g}], got {nsr!r}")
    return x


def wiener_memory_bytes(shape: tuple[int, int], channels: int, dtype: DTypeLike) -> float:
    """Peak bytes of one :func:`wiener_deconvolve` on an FFT grid of ``shape``: the padded
    image, its spectrum and the filtered product (complex, half-length), the filter,
    the regulariser's frequency grid and the inverse transform.

    Parameters
    ----------
    shape : (M, N)
        The FFT grid (:func:`fast_shape`).
    channels : int
        Channels of the image.
    dtype : float32 or float64
        The working precision.
    """
    M, N = (float(x) for x in shape)
    it = np.dtype(dtype).itemsize
    half = M * (N / 2 + 1)
    return M * N * channels * it * 2 + half * (2 * channels + 1) * 2 * it + half * it * 3


def natural_prior_scale(n_px: float) -> float:
    """2π ln(n_px / 2): ``R(f) = nsr · scale · |f|²`` for a ``1/|f|²`` signal spectrum.

    A power spectrum ``S(f) = A / |f|²`` between the lowest frequency 1/n_px and the Nyquist
    1/2 (cycles/pixel) holds the variance σ_s² = 2π A ln(n_px / 2); so with
    nsr = σ_n² / σ_s² the noise-to-signal ratio at frequency f is ``nsr · 2π ln(n_px/2) |f|²``.

    Parameters
    ----------
    n_px : float
        Size of the image, px (its geometric mean side); below 4 it counts as 4.
    """
    return 2 * np.pi * np.log(max(float(n_px) / 2, 2.0))


def working_dtype(image: np.ndarray) -> np.dtype:
    """float32 stays float32; everything else (float64, integers, bool) is float64.

    Parameters
    ----------
    image : array_like
        The image whose dtype decides.
    """
    return np.dtype(np.float32) if np.asarray(image).dtype == np.float32 else np.dtype(np.float64)


def fast_shape(shape: tuple[int, int], pad: tuple[int, int]) -> tuple[int, int]:
    """Padded (H, W) rounded up to fast real-FFT lengths (``scipy.fft.next_fast_len``).

    Parameters
    ----------
    shape : (H, W)
        The image's shape.
    pad : (int, int)
        Padding on each side of each axis, px.
    """
    return tuple(sfft.next_fast_len(int(n) + 2 * int(p), real=True) for n, p in zip(shape, pad))


def kernel_spectrum(psf: np.ndarray, shape: tuple[int, int], dtype: DTypeLike = np.float64
                   ) -> np.ndarray:
    """Transfer function of ``psf`` on an FFT grid of ``shape`` (rfft2 layout).

    Parameters
    ----------
    psf : (K, L) ndarray
        Kernel whose centre (the chief-ray image) is at ``[K // 2, L // 2]``; it is
        normalised to unit sum here.
    shape : (M, N)
        FFT grid, at least as large as the kernel.

    Returns
    -------
    (M, N // 2 + 1) complex ndarray
        ``H`` with the kernel centre moved to the origin, so that ``H = 1`` at DC and
        the phase carries no shift.
    """
    k = np.asarray(psf, dtype=dtype)
    if k.ndim != 2:
        raise ValueError(f"psf must be a 2-D kernel (K, L), got shape {k.shape}")
    if k.shape[0] > shape[0] or k.shape[1] > shape[1]:
        raise ValueError(f"psf {k.shape} is larger than the FFT grid {shape}")
    s = k.sum()
    if not np.isfinite(s) or s <= 0:
        raise ValueError("psf must have a positive, finite sum")
    big = np.zeros(shape, dtype=dtype)
    big[:k.shape[0], :k.shape[1]] = k / s
    big = np.roll(big, (-(k.shape[0] // 2), -(k.shape[1] // 2)), axis=(0, 1))
    return sfft.rfft2(big, workers=-1)


def regulariser(shape: tuple[int, int], nsr: float, prior: str, dtype: DTypeLike = np.float64,
                *, freqs: tuple[np.ndarray, np.ndarray] | None = None,
                n_px: float | None = None) -> np.ndarray:
    """Noise-to-signal power ratio R(f) on an rfft2 grid of ``shape``.

    ``nsr`` is always σ_n² / σ_s², noise variance over signal variance (what
    :meth:`mitsweep.deconv.noise.SensorNoise.nsr` gives); the prior says how the
    signal's variance is spread over frequency:

    - ``"constant"``: flat (white) signal, R = nsr at every f except DC, where R = 0 (the
      image mean is known to 1/N of the noise variance, so a constant image passes
      unchanged). Textbook, but natural images hold far less than their variance at
      high frequencies, so this under-regularises noisy images.
    - ``"natural"``: signal power falling as ``1/|f|²`` (amplitude ``1/|f|``, the
      natural-image weight W of the V metric, paper Eq. 2): ``R = nsr · 2π ln(n/2) · |f|²``
      (:func:`natural_prior_scale`), ``|f|`` in cycles/pixel; R = 0 at DC.

    ``freqs`` optionally gives the two frequency arrays (cycles/pixel), broadcastable;
    ``n_px`` the image size that sets the spectrum's lowest frequency (default the
    geometric mean of ``shape``).

    Parameters
    ----------
    shape : (M, N)
        The FFT grid; R is (M, N // 2 + 1).
    nsr : float
        Noise variance over signal variance, in [0, :data:`MAX_NSR`].
    prior : {"natural", "constant"}
        How the signal's variance spreads over frequency (above).
    dtype : dtype
        The output's precision (default float64).
    freqs : (ndarray, ndarray), optional
        Vertical and horizontal frequencies, cycles/px, broadcastable (default those of
        the rfft2 grid of ``shape``).
    n_px : float, optional
        Image size for the natural prior's scale, px.
    """
    if prior not in PRIORS:
        raise ValueError(f"prior must be one of {PRIORS}, got {prior!r}")
    nsr = check_nsr(nsr)
    if freqs is None:
        fy = sfft.fftfreq(shape[0]).astype(dtype)[:, None]
        fx = sfft.rfftfreq(shape[1]).astype(dtype)[None, :]
    else:
        fy, fx = freqs
    f2 = fy * fy + fx * fx
    if prior == "natural":
        n = float(np.sqrt(shape[0] * shape[1])) if n_px is None else float(n_px)
        return ((nsr * natural_prior_scale(n)) * f2).astype(dtype, copy=False)
    return np.where(f2 == 0, 0.0, nsr).astype(dtype)


def wiener_filter(H: np.ndarray, R: ArrayLike) -> np.ndarray:
    """``G = conj(H) / (|H|² + R)``; ``R`` an array broadcastable to ``H`` or a scalar.

    Where ``|H|² + R`` is exactly zero (a kernel spectral zero with no regularisation) G is
    set to 0: nothing can be recovered there, and 0 is the Wiener limit for R → 0⁺
    taken jointly with H → 0.

    Parameters
    ----------
    H : complex ndarray
        The kernel's transfer function (:func:`kernel_spectrum`).
    R : float or array_like
        The regulariser (:func:`regulariser`), >= 0.
    """
    den = H.real * H.real + H.imag * H.imag
    den += R
    with np.errstate(divide="ignore", invalid="ignore"):
        G = np.conj(H)
        G /= den
    bad = ~(den > 0)
    if bad.any():
        G[bad] = 0
    return G


def estimate_noise_sigma(image: np.ndarray) -> float:
    """Standard deviation of white noise in ``image`` (H, W[, C]), robust to edges.

    Donoho & Johnstone's estimator: the median absolute value of the finest diagonal
    Haar detail coefficients ``(a − b − c + d) / 2`` over 0.6745; for white noise of
    std σ those coefficients have std σ, and image structure barely reaches them.
    (scikit-image's ``estimate_sigma`` does the same with Daubechies wavelets but needs
    PyWavelets, which this package does not depend on.) Channels are pooled.

    Parameters
    ----------
    image : (H, W) or (H, W, C) array_like
        The image; below 2 × 2 pixels σ is 0.
    """
    x = np.asarray(image, dtype=np.float64)
    if x.ndim == 2:
        x = x[..., None]
    H, W = (x.shape[0] // 2) * 2, (x.shape[1] // 2) * 2
    if H < 2 or W < 2:
        return 0.0
    x = x[:H, :W]
    d = (x[0::2, 0::2] - x[0::2, 1::2] - x[1::2, 0::2] + x[1::2, 1::2]) / 2
    return float(np.median(np.abs(d)) / 0.6745)


def estimate_nsr(image: np.ndarray, *, floor: float = DEFAULT_NSR_FLOOR,
                 mask: np.ndarray | None = None) -> float:
    """Constant NSR from the image itself: σ² (wavelet MAD estimate) over signal variance.

    σ is :func:`estimate_noise_sigma` (Donoho's robust median of the finest diagonal
    Haar wavelet band), which is right for white sensor noise. The signal
    variance is the image variance minus σ² (inside ``mask`` if given). The result is
    clamped to ``[floor, 1]``: a noiseless image still gets ``floor``, a black image
    gets 1.

    Parameters
    ----------
    image : (H, W) or (H, W, C) array_like
        The image.
    floor : float
        The smallest NSR returned (default :data:`DEFAULT_NSR_FLOOR`).
    mask : (H, W) bool ndarray, optional
        Pixels whose variance counts (default all); σ is taken on the whole image.
    """
    img = np.asarray(image, dtype=np.float64)
    sigma = estimate_noise_sigma(img)
    vals = img[mask] if mask is not None else img
    var_signal = float(np.var(vals)) - sigma * sigma
    if var_signal <= 0:
        # a constant image (nothing to restore) or pure noise
        return float(floor) if sigma == 0 else 1.0
    return float(np.clip(sigma * sigma / var_signal, floor, 1.0))


def wiener_deconvolve(image: np.ndarray, psf: np.ndarray, *, nsr: float | None = None,
                      prior: str = "natural", pad: int | str = "auto",
                      pad_mode: PadMode = "symmetric", n_px: float | None = None) -> np.ndarray:
    r"""Deconvolve ``image`` by the shift-invariant ``psf`` with a Wiener filter.

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
        Blurred image, linear values (no clipping is applied, before or after).
        float32 input gives float32 output; anything else gives float64.
    psf : (K, L) ndarray
        Blur kernel, centre at ``[K // 2, L // 2]`` (any positive sum; normalised here).
        Convention: ``image = psf ⊛ sharp``, i.e. ``scipy.signal.fftconvolve(sharp, psf,
        mode="same")`` for odd K, L.
    nsr : float, optional
        Noise-to-signal power ratio of the regulariser. ``None`` estimates a constant one
        from the image (:func:`estimate_nsr`); from a sensor model use
        :meth:`mitsweep.deconv.noise.SensorNoise.nsr`.
    prior : {"natural", "constant"}
        How the signal's variance spreads over frequency: the natural-image ``1/|f|²``
        fall-off (default: with the noise model's NSR it restores noisy images
        2-5 dB better than the flat prior, measured from 50 to 0.05 lux) or flat
        (classic constant-NSR Wiener, DC exempt); see :func:`regulariser`.
    pad : int or "auto"
        Pixels of padding on each side against circular wrap-around; ``"auto"`` is twice
        the kernel size. The padded size is rounded up to a fast FFT length.
    pad_mode : str
        :func:`numpy.pad` mode for the padding; ``"symmetric"`` keeps the padded image
        continuous at the border.
    n_px : float, optional
        Size of the whole image for the natural prior's scale (default this image's
        size; tiles of a larger image pass the larger size).

    Returns
    -------
    (H, W) or (H, W, C) ndarray
        The restored image, same shape; float32 for float32 input, else float64.

    Notes
    -----
    .. math:: \hat X(f) = \frac{H^*(f)}{|H(f)|^2 + R(f)}\, Y(f)

    with :math:`H` the kernel's transfer function and :math:`R` the noise-to-signal
    power ratio (:func:`regulariser`).

    References
    ----------
    .. [1] N. Wiener, *Extrapolation, Interpolation, and Smoothing of Stationary Time
       Series*, MIT Press, 1949.
    .. [2] R. C. Gonzalez and R. E. Woods, *Digital Image Processing*, Sec. 5.8.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.signal import fftconvolve
    >>> rng = np.random.default_rng(0)
    >>> sharp = rng.random((64, 64))
    >>> psf = np.ones((5, 5)) / 25
    >>> blurred = fftconvolve(sharp, psf, mode="same")
    >>> restored = wiener_deconvolve(blurred, psf, nsr=1e-6)
    >>> restored.shape
    (64, 64)
    """
    img = np.asarray(image)
    if img.ndim not in (2, 3):
        raise ValueError(f"image must be (H, W) or (H, W, C), got shape {img.shape}")
    if img.shape[0] < 1 or img.shape[1] < 1:
        raise ValueError(f"image is empty: shape {img.shape}")
    dt = working_dtype(img)
    img = img.astype(dt, copy=False)
    check_image_values(img)
    k = np.asarray(psf)
    if k.ndim != 2:
        raise ValueError(f"psf must be (K, L), got shape {k.shape}")
    if nsr is None:
        nsr = estimate_nsr(img)
        logger.info("estimated NSR %.3g", nsr)
    nsr = check_nsr(nsr)
    if pad == "auto":
        pads = (2 * k.shape[0], 2 * k.shape[1])
    else:
        if int(pad) < 0:
            raise ValueError(f"pad must be >= 0 or 'auto', got {pad!r}")
        pads = (int(pad), int(pad))
    H_, W_ = img.shape[:2]
    M, N = fast_shape((H_, W_), pads)
    check_allocation(f"Wiener deconvolution of {W_}x{H_} px on a {N}x{M} FFT grid",
                     wiener_memory_bytes((M, N), img.shape[2] if img.ndim == 3 else 1, dt))
    pad_y0, pad_x0 = (M - H_) // 2, (N - W_) // 2
    widths = [(pad_y0, M - H_ - pad_y0), (pad_x0, N - W_ - pad_x0)] + [(0, 0)] * (img.ndim - 2)
    padded = np.pad(img, widths, mode=pad_mode) if (M, N) != (H_, W_) else img
    Hk = kernel_spectrum(k, (M, N), dtype=dt)
    G = wiener_filter(Hk, regulariser((M, N), float(nsr), prior, dtype=dt,
                                      n_px=float(np.sqrt(H_ * W_)) if n_px is None else n_px))
    if img.ndim == 3:
        G = G[..., None]
    out = sfft.irfft2(sfft.rfft2(padded, axes=(0, 1), workers=-1) * G, s=(M, N), axes=(0, 1),
                      workers=-1)
    return np.ascontiguousarray(out[pad_y0:pad_y0 + H_, pad_x0:pad_x0 + W_]).astype(dt, copy=False)
