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


#: Where each public name lives. The submodules are imported on first use (PEP 562), so
#: that ``import mitsweep.deconv`` — and every command line, which reads :data:`METHODS`
#: to build its options — does not pay for SciPy's signal and statistics modules.
_SOURCES = {
    "BankError": "bank", "IPSFBank": "bank",
    "check_bank_matches": "kernels", "grid_bank_from_radial": "kernels",
    "optical_center": "kernels", "select_depth": "kernels",
    "per_depth_band": "metrics", "per_radius": "metrics", "psnr": "metrics",
    "ssim": "metrics",
    "SensorNoise": "noise", "paper_fig10_settings": "noise",
    "BlurOperator": "operators", "polar_operator": "operators",
    "product_convolution_operator": "operators",
    "calibrated_nsr": "regularization", "noise_sigma": "regularization",
    "hqs_deconvolve": "solvers", "richardson_lucy": "solvers",
    "PolarGrid": "polar", "from_polar": "polar", "polar_deconvolve": "polar",
    "polar_grid": "polar", "to_polar": "polar",
    "scatter_blur": "spatial", "spatially_varying_blur": "spatial",
    "spatially_varying_deconvolve": "spatial",
    "estimate_nsr": "wiener", "wiener_deconvolve": "wiener",
    "deconvolve": "restore", "blur_operator": "restore",
}


def _submodule(short: str):
    """Import one submodule by its short name; literal imports, so that the architecture
    check (tests/test_architecture.py) reads every edge."""
    if short == "bank":
        from ..io import bank as mod
    elif short == "kernels":
        from . import kernels as mod
    elif short == "metrics":
        from . import metrics as mod
    elif short == "noise":
        from . import noise as mod
    elif short == "operators":
        from . import operators as mod
    elif short == "regularization":
        from . import regularization as mod
    elif short == "solvers":
        from . import solvers as mod
    elif short == "polar":
        from . import polar as mod
    elif short == "spatial":
        from . import spatial as mod
    elif short == "wiener":
        from . import wiener as mod
    else:
        from . import restore as mod
    return mod


def __getattr__(name: str):
    try:
        short = _SOURCES[name]
    except KeyError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    value = getattr(_submodule(short), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
