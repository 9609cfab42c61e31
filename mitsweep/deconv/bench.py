"""``mitsweep bench deconv``: polar and spatially varying deconvolution against a baseline.

One run, one process, side by side: the same synthetic focal-sweep image (a mosaic of
photographs at their native resolution inside the mirror's disk, blurred by the
analytic IPSF field of :mod:`mitsweep.deconv.synthetic`, with the paper's 50 lux
sensor noise) is restored by

- ``polar``: :func:`~mitsweep.deconv.polar.polar_deconvolve` with a 19-radius bank
  (the paper's Fig. 8 pipeline), resampling included in the time. ``seconds`` is the
  first call of the process, which also imports Dr.Jit (unless an earlier benchmark of
  the run did) and loads (on a machine's very first run, compiles) the resampling
  kernels; ``warm_seconds`` the median of three later calls on the same image (as
  every later frame of a sequence; ``warm_runs_seconds`` each), with its own ratios to
  the baseline and its PSNR;

(the three mitsweep methods use the noise model's NSR with the natural-image prior)

- ``spatial``: :func:`~mitsweep.deconv.spatial.spatially_varying_deconvolve` with a grid
  bank;
- ``wiener_single``: :func:`~mitsweep.deconv.wiener.wiener_deconvolve` with one IPSF
  (the one at half the mirror radius) — shift-invariant, done right;
- ``skimage_wiener``: :func:`skimage.restoration.wiener` with that same IPSF applied
  naively (``balance`` = NSR, its defaults: circular boundary, clipping); the median of
  five calls (``runs_seconds`` each), the time every ratio is taken against.

and, one entry per restoration method of :data:`mitsweep.deconv.METHODS` (key = its name),
:func:`mitsweep.deconv.deconvolve` with the radial bank and everything calibrated from
the image alone (noise σ estimated, weights chosen by the methods' rules):

- ``wiener``: polar Wiener with the discrepancy-principle NSR;
- ``rl``: damped Richardson–Lucy with the polar operator, stopped by its rule;
- ``tv``, ``hyperlaplacian``: half-quadratic splitting with those priors.

Each reports its wall time, its CPU time (all threads of this process; on a shared
machine the wall time depends on the other jobs, the CPU time much less) and its PSNR
against the sharp image inside the mirror disk.
"""

from __future__ import annotations

import argparse
import logging
import time

import numpy as np

__all__ = ["run_bench", "make_problem"]

logger = logging.getLogger(__name__)

POLAR_GOAL_S = 1.5
SPATIAL_GOAL_S = 5.0
#: Richardson–Lucy's time bound in the bench (s): it stops after the iteration past it.
RL_TIME_LIMIT_S = 60.0
#: Calls of scikit-image's ``wiener`` (the baseline) and later calls of the polar method,
#: whose median wall and CPU times are reported (the first polar call is one call).
BASELINE_REPEATS = 5
WARM_REPEATS = 3


MOSAIC = ("camera", "brick", "grass", "gravel", "astronaut", "coffee", "chelsea", "text",
          "rocket", "coins", "moon", "page")


def mosaic(size: int, tile: int = 512) -> np.ndarray:
    """(size, size) float64 grey image tiled from scikit-image's photographs at their own
    resolution (no upsampling: detail down to the pixel, as a sharp render has).

    Parameters
    ----------
    size : int
        Side of the square image, px.
    tile : int
        Side of each photograph's tile, px (default 512); a photograph smaller than a
        tile is resized to it, the tiles on the right and bottom edges are cropped.
    """
    from skimage import color, data, transform

    out = np.zeros((size, size))
    n = 0
    for y in range(0, size, tile):
        for x in range(0, size, tile):
            img = getattr(data, MOSAIC[n % len(MOSAIC)])()
            n += 1
            if img.ndim == 3:
                img = color.rgb2gray(img[..., :3])
            elif img.dtype == np.uint8:
                img = img / 255.0
            img = img[:tile, :tile]
            if img.shape != (tile, tile):
                img = transform.resize(img, (tile, tile), anti_aliasing=True)
            h, w = min(tile, size - y), min(tile, size - x)
            out[y:y + h, x:x + w] = img[:h, :w]
    return out


def make_problem(size: int, *, kernel_size: int, grid: int, seed: int = 0) -> dict:
    """The benchmark's sharp image, blurred noisy image, banks and mask.

    Parameters
    ----------
    size : int
        Side of the square image, px; the mirror's disk has radius 0.47 ``size``.
    kernel_size : int
        Side of the synthetic IPSF kernels, px (odd).
    grid : int
        Points per side of the grid bank given to the spatially varying method.
    seed : int
        Seed of the sensor noise (the paper's Fig. 10 sweep exposure, 6.4 µm pixels).

    Returns
    -------
    dict
        ``sharp`` and ``blurred`` (float32), ``mask`` (the mirror's disk), the banks
        ``radial`` (19 radii) and ``grid``, ``single`` (the IPSF at half the mirror's
        radius), ``nsr`` (the noise model's) and ``r_mirror`` (px).
    """

    from .kernels import select_depth
    from .metrics import disk_mask
    from .noise import paper_fig10_settings
    from .spatial import spatially_varying_blur
    from .synthetic import synthetic_grid_bank, synthetic_radial_bank

    shape = (size, size)
    r_mirror = 0.47 * size
    sharp = mosaic(size, tile=min(512, size // 2))
    mask = disk_mask(shape, r_mirror)
    sharp = np.where(mask, sharp, 0.0)
    # the "truth" blur: the analytic model on a fine grid (product-convolution with a
    # kernel every ~size/48 px, much finer than the model's variation)
    fine = synthetic_grid_bank(shape, (49, 49), size=kernel_size, r_max_px=r_mirror)
    blurred = spatially_varying_blur(sharp, fine)
    noise = paper_fig10_settings(pixel_pitch=0.0064)["sweep"]
    # expose like a metered camera: the brightest scene point just below saturation
    scale = 0.9 * noise.saturation / float(sharp.max())
    noisy = noise.apply(blurred * scale, rng=seed) / scale
    nsr = noise.nsr(mean_level=float(sharp[mask].mean() * scale),
                    signal_std=float(sharp[mask].std() * scale))
    radial = synthetic_radial_bank(shape, size=kernel_size, r_max_px=r_mirror, n_radii=19)
    gridbank = synthetic_grid_bank(shape, (grid, grid), size=kernel_size, r_max_px=r_mirror)
    single = select_depth(radial)[9]       # the IPSF at half the mirror radius
    return dict(sharp=sharp.astype(np.float32), blurred=noisy.astype(np.float32),
                mask=mask, radial=radial, grid=gridbank, single=single, nsr=nsr,
                r_mirror=r_mirror)


def _timed(fn, *a, **kw):
    """(result, wall seconds, CPU seconds of this process: all its threads)."""
    c0, t0 = time.process_time(), time.perf_counter()
    out = fn(*a, **kw)
    return out, time.perf_counter() - t0, time.process_time() - c0


def run_bench(args: argparse.Namespace) -> dict:
    """Run the benchmark described in this module's docstring.

    Parameters
    ----------
    args : argparse.Namespace
        The command line's options; only ``quick`` is read (a 256 px image with 15 px
        kernels and an 8x8 grid instead of 2048 px, 31 px and 16x16; no time goals).

    Returns
    -------
    dict
        The image's description, the kernel size, the NSR, the blurred image's PSNR and
        the setup time, then one entry per method (wall and CPU seconds, PSNR, their
        ratios and gains against scikit-image's ``wiener``).
    """
    from skimage.restoration import wiener as sk_wiener

    from .metrics import psnr
    from .polar import polar_deconvolve
    from .spatial import spatially_varying_deconvolve
    from . import METHODS, deconvolve
    from .wiener import wiener_deconvolve

    quick = bool(getattr(args, "quick", False))
    size = 256 if quick else 2048
    K = 15 if quick else 31
    grid = 8 if quick else 16
    t0 = time.perf_counter()
    p = make_problem(size, kernel_size=K, grid=grid)
    setup_s = time.perf_counter() - t0
    y, sharp, mask, nsr = p["blurred"], p["sharp"], p["mask"], p["nsr"]

    def score(img):
        return psnr(img, sharp, mask=mask)

    runs = {}

    def record(name, fn, *a, **kw):
        out, wall, cpu = _timed(fn, *a, **kw)
        runs[name] = {"seconds": wall, "cpu_seconds": cpu, "psnr_db": score(out)}

    def median_of(n, fn, *a, **kw):
        """(output, median wall s, median CPU s, every wall s) of n calls."""
        times = [_timed(fn, *a, **kw) for _ in range(n)]
        walls = [t[1] for t in times]
        return (times[0][0], float(np.median(walls)), float(np.median([t[2] for t in times])),
                walls)

    record("polar", polar_deconvolve, y, p["radial"], nsr=nsr, prior="natural")
    # the same call again: Dr.Jit imported, its kernels loaded, NumPy's memory warm
    out, wall, cpu, walls = median_of(WARM_REPEATS, polar_deconvolve, y, p["radial"],
                                      nsr=nsr, prior="natural")
    runs["polar"].update(warm_seconds=wall, warm_cpu_seconds=cpu, warm_psnr_db=score(out),
                         warm_runs_seconds=walls)
    record("spatial", spatially_varying_deconvolve, y, p["grid"], nsr=nsr, prior="natural")
    runs["spatial"]["grid"] = f"{grid}x{grid}"
    record("wiener_single", wiener_deconvolve, y, p["single"], nsr=nsr, prior="natural")
    # the baseline is short (0.1-0.3 s here) and these machines are noisy: its median
    out, wall, cpu, walls = median_of(BASELINE_REPEATS, sk_wiener, y, p["single"], nsr)
    runs["skimage_wiener"] = {"seconds": wall, "cpu_seconds": cpu, "psnr_db": score(out),
                              "runs_seconds": walls}
    for method in METHODS:
        kw = {"time_limit_s": RL_TIME_LIMIT_S} if method == "rl" else {}
        record(method, deconvolve, y, p["radial"], method=method, **kw)
    base = runs["skimage_wiener"]
    mp = size * size / 1e6
    for name in ("polar", "spatial", "wiener_single") + METHODS:
        runs[name]["time_ratio_vs_skimage"] = runs[name]["seconds"] / base["seconds"]
        runs[name]["cpu_ratio_vs_skimage"] = runs[name]["cpu_seconds"] / base["cpu_seconds"]
        runs[name]["psnr_gain_vs_skimage_db"] = runs[name]["psnr_db"] - base["psnr_db"]
    runs["polar"]["warm_time_ratio_vs_skimage"] = runs["polar"]["warm_seconds"] / base["seconds"]
    runs["polar"]["warm_cpu_ratio_vs_skimage"] = (runs["polar"]["warm_cpu_seconds"]
                                                  / base["cpu_seconds"])
    for name in METHODS:
        runs[name]["seconds_per_megapixel"] = runs[name]["seconds"] / mp
        runs[name]["psnr_gain_vs_polar_db"] = runs[name]["psnr_db"] - runs["polar"]["psnr_db"]
    best = max(("tv", "hyperlaplacian", "rl"), key=lambda m: runs[m]["psnr_db"])
    result = {
        "image": f"{size}x{size} float32, mirror disk radius {p['r_mirror']:.0f} px",
        "kernel_px": K, "nsr": nsr, "blurred_psnr_db": score(y), "setup_seconds": setup_s,
        "best_prior_method": best, **runs,
    }
    if not quick:
        result["polar"]["goal_s"] = POLAR_GOAL_S
        result["polar"]["meets_goal"] = runs["polar"]["seconds"] < POLAR_GOAL_S
        result["spatial"]["goal_s"] = SPATIAL_GOAL_S
        result["spatial"]["meets_goal"] = runs["spatial"]["seconds"] < SPATIAL_GOAL_S
    return result
