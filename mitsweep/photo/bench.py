"""``mitsweep bench calibrate``: finding a mirror in a large photo, against a baseline.

One run, one process, side by side, on the same synthetic photo (a textured mirror disc
with a soft, noisy rim against a textured background, its centre and radius known to the
benchmark; 24 MP, or 4 MP with ``--quick``, float32 RGB as :mod:`mitsweep.io.camera`
returns a JPEG):

- ``setup``: :func:`~mitsweep.photo.calibrate_photo` with a circle outline whose
  predicted size is 9% off (a guessed pitch), as ``mitsweep calibrate --setup`` does;
- ``free``: :func:`~mitsweep.photo.free.find_circle`, as ``mitsweep calibrate --free``;
- ``skimage``: the independent reference the tests use on real photos, scikit-image's
  Canny edges then a RANSAC ``CircleModel`` and a least-squares refit on its inliers,
  on the same photo's luminance (given the annulus to look in, which mitsweep is not).

Each reports its wall time and its centre and radius errors (px) against the truth.
Decoding the file is not timed (it is the same for all; a 24 MP JPEG takes ~2 s here).
"""

from __future__ import annotations

import argparse
import logging
import time
from dataclasses import replace

import numpy as np

__all__ = ["run_bench", "make_photo"]

logger = logging.getLogger(__name__)

#: Side (px) of the square benchmark photo: 4900² = 24 MP; 2000² with ``--quick``.
SIDE_PX, QUICK_SIDE_PX = 4900, 2000


def make_photo(side: int, *, seed: int = 0) -> tuple[np.ndarray, tuple[float, float], float]:
    """A synthetic (side, side, 3) float32 photo of a mirror disc; its centre (row, col)
    and radius, px.

    Parameters
    ----------
    side : int
        Side of the square photo, px.
    seed : int
        Seed of the texture's random phases (the same seed gives the same photo).
    """
    from scipy.special import expit

    rng = np.random.default_rng(seed)
    centre = (0.5 * side + 0.037 * side + 0.31, 0.5 * side - 0.021 * side - 0.47)
    radius = 0.41 * side + 0.23
    step = max(1, side // 1000)  # the texture drawn on a grid of ~1000² then upscaled
    n = side // step + 1
    yy, xx = np.mgrid[0:n, 0:n].astype(np.float32) * step
    r = np.hypot(yy - centre[0], xx - centre[1])
    phi = np.arctan2(yy - centre[0], xx - centre[1])
    inside = 0.55 + 0.25 * np.sin(9 * phi + 0.02 * r) * np.cos(0.05 * r)
    outside = 0.30 + 0.10 * np.sin(0.013 * xx) * np.cos(0.017 * yy)
    blend = expit((radius - r) / (1.5 * step))  # a soft rim
    coarse = (inside * blend + outside * (1 - blend)).astype(np.float32)
    lum = np.repeat(np.repeat(coarse, step, 0), step, 1)[:side, :side]
    # the rim again at full resolution: the upscaling must not move it
    rows = np.arange(side, dtype=np.float32)[:, None]
    cols = np.arange(side, dtype=np.float32)[None, :]
    rr = np.hypot(rows - centre[0], cols - centre[1])
    edge = expit((radius - rr) / 1.5)
    lum = np.where(np.abs(rr - radius) < 6 * step, 0.30 + 0.25 * edge, lum)
    lum += rng.normal(0.0, 0.01, lum.shape).astype(np.float32)
    photo = np.stack([lum * 0.9, lum, lum * 1.1], axis=-1).astype(np.float32)
    return np.clip(photo, 0.0, None), centre, radius


def _circle_setup(radius_px: float, shape: tuple[int, int], error: float):
    """The bundled paraboloid (a rim outline: a circle) at the pitch that predicts the
    disc ``1 + error`` times its size."""
    from ..config import Sensor, load_setup
    from ..optics.outline import predicted_outline
    from ..resources import bundled_setup

    base = load_setup(bundled_setup("paraboloid"))
    pitch = predicted_outline(base).equivalent_radius_px(1.0) / (radius_px * (1 + error))
    return replace(base, sensor=Sensor(resolution=(shape[1], shape[0]), pixel_pitch=pitch))


def _skimage_circle(lum: np.ndarray, centre, radius) -> tuple[tuple[float, float], float]:
    from skimage.feature import canny
    from skimage.measure import CircleModel, ransac

    rr, cc = np.mgrid[0:lum.shape[0], 0:lum.shape[1]]
    annulus = np.abs(np.hypot(rr - centre[0], cc - centre[1]) - radius) < 0.05 * radius
    edges = canny(lum, sigma=2.0, mask=annulus)
    pts = np.column_stack(np.nonzero(edges)).astype(np.float64)
    _, inliers = ransac(pts[:, ::-1], CircleModel, min_samples=3, residual_threshold=2.0,
                            max_trials=200, rng=0)
    refit = CircleModel.from_estimate(pts[inliers][:, ::-1])
    (xc, yc), r = refit.center, refit.radius
    return (float(yc), float(xc)), float(r)


def _errors(found_centre, found_radius, centre, radius) -> dict:
    return {"centre_error_px": float(np.max(np.abs(np.subtract(found_centre, centre)))),
            "radius_error_px": float(abs(found_radius - radius))}


def run_bench(args: argparse.Namespace) -> dict:
    """The benchmark (see the module docstring): one dict of results.

    Parameters
    ----------
    args : argparse.Namespace
        The command's options: ``quick`` (bool) chooses the smaller photo
        (:data:`QUICK_SIDE_PX` instead of :data:`SIDE_PX`).
    """
    from . import calibrate_photo, luminance
    from .free import find_circle

    side = QUICK_SIDE_PX if getattr(args, "quick", False) else SIDE_PX
    photo, centre, radius = make_photo(side)
    out: dict = {"photo": {"side_px": side, "megapixels": side * side / 1e6,
                           "centre_px": list(centre), "radius_px": radius}}
    setup = _circle_setup(radius, photo.shape[:2], error=0.09)
    t0 = time.perf_counter()
    cal = calibrate_photo(photo, setup)
    out["setup"] = {"seconds": time.perf_counter() - t0,
                    **_errors(cal.center_px, cal.rim_radius_px, centre, radius)}
    t0 = time.perf_counter()
    fit, found = find_circle(photo)
    out["free"] = {"seconds": time.perf_counter() - t0,
                   **_errors(fit.center_px, found, centre, radius)}
    t0 = time.perf_counter()
    lum = luminance(photo)
    c, r = _skimage_circle(lum, centre, radius)
    out["skimage"] = {"seconds": time.perf_counter() - t0, **_errors(c, r, centre, radius)}
    for k in ("setup", "free"):
        out[k]["ratio_to_skimage"] = out[k]["seconds"] / max(out["skimage"]["seconds"], 1e-9)
    logger.info("bench calibrate: %s", out)
    return out
