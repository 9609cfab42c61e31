"""``mitsweep.deconv``: EDOF recovery by deconvolution, sensor noise and image metrics.

NumPy/SciPy (and scikit-image for SSIM) only: this package never imports Mitsuba or
Dr.Jit. The noise level of an image is estimated here (:func:`estimate_nsr`: a robust
median of the finest diagonal Haar wavelet band), not by scikit-image.

- :func:`wiener_deconvolve` — shift-invariant Wiener, padded, stated regulariser;
- :func:`polar_deconvolve` — rotationally symmetric setups (radial banks, paper Fig. 8);
- :func:`spatially_varying_deconvolve` — any setup (grid banks, product-convolution);
- :func:`deconvolve` — one entry for every restoration method (:data:`METHODS`), with
  the right operator for the bank's kind;
- :mod:`.operators` — the spatially varying blur as a forward/adjoint pair (polar and
  product-convolution), also as a ``pylops.LinearOperator``;
- :mod:`.solvers` — Richardson–Lucy and half-quadratic splitting with TV and
  hyper-Laplacian priors;
- :mod:`.regularization` — NSR and prior weights from the noise and the image;
- :class:`SensorNoise` — Poisson–Gaussian noise from lux, f-number, exposure, ISO;
- :mod:`.metrics` — PSNR/SSIM inside a mask, per radius and per depth band.
"""

from __future__ import annotations

from .methods import METHODS

__all__ = ["deconvolve", "METHODS", "wiener_deconvolve", "polar_deconvolve",
           "spatially_varying_deconvolve", "spatially_varying_blur", "scatter_blur",
           "estimate_nsr", "SensorNoise", "paper_fig10_settings", "psnr", "ssim",
           "per_radius", "per_depth_band", "PolarGrid", "polar_grid", "to_polar",
           "from_polar", "select_depth", "check_bank_matches", "grid_bank_from_radial",
           "optical_center", "BankError", "IPSFBank", "BlurOperator", "polar_operator",
           "product_convolution_operator", "blur_operator", "richardson_lucy",
           "hqs_deconvolve", "calibrated_nsr", "noise_sigma"]


import lazy_loader as _lazy

from ..io.bank import BankError, IPSFBank

#: Where each public name lives. The submodules are imported on first use (PEP 562, through
#: ``lazy_loader``, scikit-image's choice), so that ``import mitsweep.deconv`` (and every
#: command line, which reads :data:`METHODS` to build its options) does not pay for SciPy's
#: signal and statistics modules. The bank's types come from :mod:`mitsweep.io.bank`.
__getattr__, _lazy_dir, _ = _lazy.attach(__name__, submod_attrs={
    "kernels": ["check_bank_matches", "grid_bank_from_radial", "optical_center",
                "select_depth"],
    "metrics": ["per_depth_band", "per_radius", "psnr", "ssim"],
    "noise": ["SensorNoise", "paper_fig10_settings"],
    "operators": ["BlurOperator", "polar_operator", "product_convolution_operator"],
    "regularization": ["calibrated_nsr", "noise_sigma"],
    "solvers": ["hqs_deconvolve", "richardson_lucy"],
    "polar": ["PolarGrid", "from_polar", "polar_deconvolve", "polar_grid", "to_polar"],
    "spatial": ["scatter_blur", "spatially_varying_blur", "spatially_varying_deconvolve"],
    "wiener": ["estimate_nsr", "wiener_deconvolve"],
    "restore": ["deconvolve", "blur_operator"],
})


def __dir__() -> list[str]:
    return sorted(set(_lazy_dir()) | set(__all__) | set(globals()))
