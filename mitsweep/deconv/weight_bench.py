"""The weight choice against the oracle: chosen NSR vs the best NSR, before and after.

:func:`weight_rows` scores any set of candidate weights for one image against the oracle
weight (:func:`mitsweep.deconv.budget.oracle_weight`: the NSR whose restoration is
nearest the truth); :func:`independent_blur_problem` is the issue's test case (a
spatially varying blur that is *not* the deconvolver's model: a 49 × 49 product
convolution of the synthetic IPSF field, restored by the polar method with a 19-radius
bank, white Gaussian noise σ); :func:`synthetic_weight_bench` runs it at each size and σ,
with the former blind estimate (``nsr=None``: σ²/variance), the noise-model NSR
(:func:`~mitsweep.deconv.weights.model_nsr` with the known σ), the new blind one
(:func:`~mitsweep.deconv.weights.blind_nsr`) and the noise-model NSR on the disk's own
spectrum (``spectrum="mirror"``), side by side in one process. The datasets'
version is :func:`mitsweep.pipeline.weight_bench.dataset_weight_bench`;
``scripts/weight_bench.py`` prints both.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence

import numpy as np

__all__ = ["weight_rows", "independent_blur_problem", "synthetic_weight_bench",
           "format_rows"]

logger = logging.getLogger(__name__)


def weight_rows(image: np.ndarray, truth: np.ndarray,
                restore: Callable[[np.ndarray, float], np.ndarray],
                candidates: dict[str, float], *, mask: np.ndarray | None = None,
                bounds: tuple[float, float] = (1e-10, 1.0)) -> dict:
    """The oracle weight of ``image`` and each candidate's PSNR and loss against it.

    Returns ``{"oracle": {"weight", "psnr_db"}, name: {"weight", "psnr_db",
    "loss_db"}, ...}`` (PSNR over ``mask``, data range 1; ``loss_db`` = oracle −
    candidate, ≥ 0 up to the oracle search's tolerance).

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
        The blurred, noisy image.
    truth : ndarray
        The sharp image, the shape of ``image``.
    restore : callable
        ``restore(image, weight) -> restored image``.
    candidates : dict of str to float
        The weights to score, by name.
    mask : (H, W) bool ndarray, optional
        Pixels that count (default all).
    bounds : (float, float)
        Range of the oracle's weight search (default 1e-10 to 1).
    """
    from .budget import _mse_map, oracle_weight

    m = np.ones(np.shape(truth)[:2], bool) if mask is None else np.asarray(mask, bool)
    w, _, mse = oracle_weight(image, truth, restore, mask=m, bounds=bounds)
    best = -10 * math.log10(mse)
    out: dict = {"oracle": {"weight": float(w), "psnr_db": best}}
    for name, nsr in candidates.items():
        p = -10 * math.log10(float(_mse_map(restore(image, nsr), truth)[m].mean()))
        out[name] = {"weight": float(nsr), "psnr_db": p, "loss_db": best - p}
    return out


def independent_blur_problem(size: int = 512, sigma: float = 0.005, *, seed: int = 0,
                             kernel_size: int | None = None) -> dict:
    """The bench mosaic inside a disk of radius 0.47 size, blurred by a 49 × 49 grid
    product-convolution of the synthetic IPSF field (independent of the polar
    deconvolver's own model), plus white Gaussian noise ``sigma``; the 19-radius radial
    bank to restore it with. Returns ``sharp``, ``blurred``, ``mask``, ``bank``,
    ``sigma``.

    Parameters
    ----------
    size : int
        Side of the square image, px (default 512).
    sigma : float
        Standard deviation of the noise, relative exposure (default 0.005).
    seed : int
        Seed of the noise.
    kernel_size : int, optional
        Kernel side, px (default 15 up to 256 px, 21 up to 1024 px, 31 beyond).
    """
    from .bench import mosaic
    from .metrics import disk_mask
    from .spatial import spatially_varying_blur
    from .synthetic import synthetic_grid_bank, synthetic_radial_bank

    K = kernel_size or (15 if size <= 256 else 21 if size <= 1024 else 31)
    shape = (int(size), int(size))
    r = 0.47 * size
    mask = disk_mask(shape, r)
    sharp = np.where(mask, mosaic(size, tile=min(512, size // 2)), 0.0)
    blurred = spatially_varying_blur(sharp, synthetic_grid_bank(shape, (49, 49), size=K,
                                                                r_max_px=r))
    noisy = blurred + np.random.default_rng(seed).normal(0.0, sigma, shape)
    return {"sharp": sharp, "blurred": noisy, "mask": mask, "sigma": float(sigma),
            "bank": synthetic_radial_bank(shape, size=K, r_max_px=r, n_radii=19)}


def synthetic_weight_bench(sizes: Sequence[int] = (512,),
                           sigmas: Sequence[float] = (0.005, 0.001), *,
                           seed: int = 0) -> list[dict]:
    """:func:`weight_rows` on :func:`independent_blur_problem` for each size and σ:
    ``before`` (polar Wiener's ``nsr=None``, the variance-based estimate), ``model``
    (the known σ), ``blind`` (nothing known) and ``mirror`` (the known σ, the spectrum
    read over the disk: ``model_nsr(..., spectrum="mirror")``). One row per case, with
    ``seconds`` of the model and blind rules' NSR choice.

    Parameters
    ----------
    sizes : sequence of int
        Image sides, px (default 512).
    sigmas : sequence of float
        Noise standard deviations, relative exposure (default 0.005 and 0.001).
    seed : int
        Seed of the noise of every case.
    """
    from .polar import polar_deconvolve
    from .wiener import estimate_nsr
    from .weights import blind_nsr, model_nsr

    rows = []
    for size in sizes:
        for sigma in sigmas:
            p = independent_blur_problem(size, sigma, seed=seed)
            y, bank, mask = p["blurred"], p["bank"], p["mask"]
            t0 = time.perf_counter()
            model = model_nsr(y, bank, sigma, mask=mask)
            t1 = time.perf_counter()
            blind = blind_nsr(y, bank, mask=mask)
            t2 = time.perf_counter()

            def restore(x: np.ndarray, w: float, bank=bank) -> np.ndarray:
                return polar_deconvolve(x, bank, nsr=w)

            mirror = model_nsr(y, bank, sigma, mask=mask, spectrum="mirror")
            r = weight_rows(y, p["sharp"], restore,
                            {"before": estimate_nsr(y), "model": model, "blind": blind,
                             "mirror": mirror}, mask=mask)
            rows.append({"case": f"independent blur {size} px, sigma {sigma:g}",
                         "model_seconds": t1 - t0, "blind_seconds": t2 - t1, **r})
    return rows


def format_rows(rows: list[dict], names: tuple[str, ...]) -> str:
    """A text table: per case the oracle's NSR and PSNR, then each named rule's NSR
    and its loss against the oracle (dB).

    Parameters
    ----------
    rows : list of dict
        :func:`weight_rows` outputs, each with its ``case`` name.
    names : tuple of str
        The rules to show, as columns; a rule a row lacks shows ``-``.
    """
    head = f"{'case':<44s} {'oracle NSR':>10s} {'dB':>6s}" + "".join(
        f" {n + ' NSR':>12s} {'loss dB':>7s}" for n in names)
    lines = [head]
    for r in rows:
        line = f"{r['case']:<44s} {r['oracle']['weight']:10.3g} {r['oracle']['psnr_db']:6.2f}"
        for n in names:
            if n in r:
                line += f" {r[n]['weight']:12.3g} {r[n]['loss_db']:7.2f}"
            else:
                line += f" {'-':>12s} {'-':>7s}"
        lines.append(line)
    return "\n".join(lines) + "\n"
