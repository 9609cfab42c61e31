"""``mitsweep.deconv``: EDOF recovery by deconvolution, sensor noise and image metrics.

NumPy/SciPy (and scikit-image for SSIM) only: this package never imports Mitsuba or
Dr.Jit. The noise level of an image is estimated here (:func:`estimate_nsr`: a robust
median of the finest diagonal Haar wavelet band), not by scikit-image.

- :func:`wiener_deconvolve` — shift-invariant Wiener, padded, stated regulariser;
- :func:`polar_deconvolve` — rotationally symmetric setups (radial banks, paper Fig. 8);
- :func:`spatially_varying_deconvolve` — any setup (grid banks, product-convolution);
- :func:`deconvolve` — picks one of the two from the bank's kind;
- :class:`SensorNoise` — Poisson–Gaussian noise from lux, f-number, exposure, ISO;
- :mod:`.metrics` — PSNR/SSIM inside a mask, per radius and per depth band.
"""

from __future__ import annotations

import numpy as np

from ..io.bank import BankError, IPSFBank
from .kernels import (check_bank_matches, grid_bank_from_radial, optical_center,
                      select_depth)
from .metrics import per_depth_band, per_radius, psnr, ssim
from .noise import SensorNoise, paper_fig10_settings
from .polar import PolarGrid, from_polar, polar_deconvolve, polar_grid, to_polar
from .spatial import scatter_blur, spatially_varying_blur, spatially_varying_deconvolve
from .wiener import estimate_nsr, wiener_deconvolve

__all__ = ["deconvolve", "METHODS", "wiener_deconvolve", "polar_deconvolve",
           "spatially_varying_deconvolve", "spatially_varying_blur", "scatter_blur",
           "estimate_nsr", "SensorNoise", "paper_fig10_settings", "psnr", "ssim",
           "per_radius", "per_depth_band", "PolarGrid", "polar_grid", "to_polar",
           "from_polar", "select_depth", "check_bank_matches", "grid_bank_from_radial",
           "optical_center", "BankError", "IPSFBank"]


#: Restoration methods :func:`deconvolve` accepts (``method=``); every command that makes
#: an EDOF image offers these names.
METHODS: tuple[str, ...] = ("wiener",)


def deconvolve(image: np.ndarray, bank: IPSFBank, *, method: str = "wiener", **kw) -> np.ndarray:
    """Restore a focal-sweep image with ``method`` and the right operator for ``bank``.

    ``method="wiener"``: a ``kind="radial"`` bank (untilted, rotationally symmetric
    setup) goes to :func:`polar_deconvolve`; a ``kind="grid"`` bank to
    :func:`spatially_varying_deconvolve`. Keyword arguments are passed on (both take
    ``nsr``, ``prior`` and ``depth_mm``). Other names of :data:`METHODS` are the
    prior-based solvers.
    """
    if method not in METHODS:
        raise ValueError(f"unknown restoration method {method!r}; allowed: {', '.join(METHODS)}")
    if bank.kind == "radial":
        return polar_deconvolve(image, bank, **kw)
    if bank.kind == "grid":
        return spatially_varying_deconvolve(image, bank, **kw)
    raise BankError(f"unknown bank kind {bank.kind!r}")
