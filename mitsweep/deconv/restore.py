"""One entry point for every restoration method: :func:`deconvolve`, :func:`blur_operator`."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from numpy.typing import DTypeLike

from ..deprecation import renamed_keywords
from ..io.bank import BankError, IPSFBank
from .methods import METHODS
from .noise import SensorNoise
from .operators import BlurOperator, polar_operator, product_convolution_operator
from .polar import polar_deconvolve
from .regularization import calibrated_nsr, gcv_noise, noise_sigma, surrogate_kernel
from .solvers import hqs_deconvolve, richardson_lucy
from .spatial import spatially_varying_deconvolve
from .wiener import working_dtype

__all__ = ["deconvolve", "blur_operator"]


@renamed_keywords(depth_mm="depth")
def blur_operator(bank: IPSFBank, image_shape: tuple[int, ...], *,
                  depth: float | str | None = None,
                  center: tuple[float, float] | None = None,
                  dtype: DTypeLike = np.float64) -> BlurOperator:
    """The bank's blur on (H, W) images: polar for a radial bank, product-convolution
    for a grid bank.

    Parameters
    ----------
    bank : IPSFBank
        A radial or grid bank.
    image_shape : tuple of int
        The image's (H, W[, C]); the operator acts on (H, W).
    depth : float, "mean" or None
        The bank depth, as in :func:`~mitsweep.deconv.kernels.select_depth` (default
        500 mm).
    center : (float, float), optional
        The pole (row, col), px, of a radial bank (default the optical axis); a grid
        bank takes none.
    dtype : float32 or float64
        The polar operator's working precision (the product-convolution operator works
        in its input's).
    """
    shape = (int(image_shape[0]), int(image_shape[1]))
    if bank.kind == "radial":
        return polar_operator(bank, shape, depth=depth, center=center, dtype=dtype)
    if bank.kind == "grid":
        if center is not None:
            raise ValueError("center applies to radial banks (polar deconvolution) only")
        return product_convolution_operator(bank, shape, depth=depth)
    raise BankError(f"unknown bank kind {bank.kind!r}")


@renamed_keywords(depth_mm="depth")
def deconvolve(image: np.ndarray, bank: IPSFBank, *, method: str = "wiener",
               weight: float | None = None, iterations: int | None = None,
               noise: SensorNoise | float | None = None, progress: bool = False, **kw: Any
              ) -> np.ndarray:
    """Restore a focal-sweep image with ``method`` and the right operator for ``bank``.

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
        Focal-sweep image on the bank's reference pixel grid; float32 stays float32.
    bank : IPSFBank
        ``kind="radial"`` (polar operators and filters) or ``kind="grid"``
        (product-convolution).
    method : {"wiener", "rl", "tv", "hyperlaplacian"}
        ``"wiener"``: :func:`polar_deconvolve` or :func:`spatially_varying_deconvolve`;
        ``"rl"``: damped Richardson–Lucy (:func:`~mitsweep.deconv.solvers.richardson_lucy`)
        with :func:`blur_operator`; ``"tv"``, ``"hyperlaplacian"``: half-quadratic
        splitting (:func:`~mitsweep.deconv.solvers.hqs_deconvolve`).
    weight : float, optional
        Wiener: the NSR; TV / hyper-Laplacian: the prior weight λ; None: calibrated
        from the noise and the image (Wiener: discrepancy principle,
        :func:`~mitsweep.deconv.regularization.calibrated_nsr`, natural prior only;
        priors: :func:`~mitsweep.deconv.regularization.prior_weight`). Richardson–Lucy
        has no weight (its regularisation is its stopping rule).
    iterations : int, optional
        RL iterations or HQS β steps; None: the method's stopping rule / schedule.
        Wiener is not iterative.
    noise : SensorNoise, float or None
        The image's noise (:func:`~mitsweep.deconv.regularization.noise_sigma`); None:
        estimated from the image.
    progress : bool
        A tqdm bar on stderr for the iterative methods.
    **kw
        Passed on: ``depth`` (mm; its former name ``depth_mm`` is still accepted, with a
        :class:`DeprecationWarning`) and ``center`` (radial banks) for every method;
        ``nsr`` and ``prior`` for Wiener (``nsr`` is the former name of ``weight``);
        for TV / hyper-Laplacian ``nsr`` fixes the NSR of their first (Wiener) step
        (default: calibrated) and ``time_limit_s`` bounds their time; for RL ``nsr``
        has no meaning and is ignored, ``damping``, ``boundary`` and ``time_limit_s`` are
        RL's (its limit bounds the whole call, operator built and all channels).
    """
    if method not in METHODS:
        raise ValueError(f"unknown restoration method {method!r}; allowed: {', '.join(METHODS)}")
    if bank.kind not in ("radial", "grid"):
        raise BankError(f"unknown bank kind {bank.kind!r}")
    if method == "wiener":
        if iterations is not None:
            raise ValueError("method 'wiener' is not iterative: iterations must be None")
        nsr = kw.pop("nsr", None)
        if weight is not None and nsr is not None:
            raise ValueError("give weight or nsr (its former name), not both")
        nsr = weight if weight is not None else nsr
        if nsr is None and kw.get("prior", "natural") == "natural":
            nsr = calibrated_nsr(image, bank, noise=noise, depth=kw.get("depth"),
                                 center=kw.get("center"))
        if bank.kind == "radial":
            return polar_deconvolve(image, bank, nsr=nsr, **kw)
        if "center" in kw and kw["center"] is not None:
            raise ValueError("center applies to radial banks (polar deconvolution) only")
        kw.pop("center", None)
        return spatially_varying_deconvolve(image, bank, nsr=nsr, **kw)
    if "prior" in kw:
        raise ValueError(f"prior= is Wiener's; method {method!r} sets its own prior")
    if method == "rl":
        if weight is not None:
            raise ValueError("method 'rl' takes no weight: its stopping rule regularises")
        kw.pop("nsr", None)
        t0 = time.perf_counter()
        img = np.asarray(image)
        depth, center = kw.pop("depth", None), kw.pop("center", None)
        op = blur_operator(bank, img.shape, depth=depth, center=center,
                           dtype=working_dtype(img))
        limit = kw.pop("time_limit_s", None)
        chans = [img] if img.ndim == 2 else [img[..., c] for c in range(img.shape[2])]
        k_mid = surrogate_kernel(bank, img.shape, depth=depth, center=center)
        outs = []
        for c, chan in enumerate(chans):
            # the limit is the whole call's (building the operator counts), shared
            # evenly by the channels still to do
            left = None if limit is None else \
                max(0.0, (float(limit) - (time.perf_counter() - t0)) / (len(chans) - c))
            # the stopping rule's σ: as the priors', everything blur plus noise does not
            # explain counts (GCV's σ; the wavelet σ alone missed a fifth of a 0.5-lux
            # image's Poisson–Gaussian noise, and RL ran on into it: 19.3 dB against the
            # blurred image's 22.4)
            sigma = max(noise_sigma(chan, noise), gcv_noise(chan, k_mid)[1])
            outs.append(richardson_lucy(chan, op, iterations=iterations, noise=sigma,
                                        progress=progress, time_limit_s=left, **kw))
        return outs[0] if img.ndim == 2 else np.stack(outs, axis=-1)
    return hqs_deconvolve(image, bank, prior=method, weight=weight, iterations=iterations,
                          noise=noise, progress=progress, **kw)
