"""Find a mirror's outline in a photo without a setup: :func:`find_circle`.

Where no setup exists yet (a new camera, an unknown mirror), the outline is taken to be
a circle, the image of an untilted mirror's rim or limb, of unknown centre and radius.
The coarse search (:mod:`mitsweep.photo.coarse`) runs once per octave of radius, from
:data:`MIN_RADIUS_SHARE` of the photo's shorter side to :data:`MAX_RADIUS_SHARE` of its
longer one (a rim clipped by the frame is larger than the frame), each on a copy reduced
for that octave; the strongest candidates are refined and validated as a setup's
outline is (:func:`mitsweep.photo.rim.fit_rim`), and the validated one whose edge stands
out most from its surroundings is kept.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from ..optics.outline import RimOutline
from .coarse import coarse_search, search_scales
from .image import fill_void, photo_void, reduce_by
from .rim import CalibrationError, NoMirrorError, RimFit, fit_rim, working_luminance

__all__ = ["find_circle", "circle_outline", "ellipse_of_edges", "MIN_RADIUS_SHARE",
           "MAX_RADIUS_SHARE", "CANDIDATES", "ELLIPSE_SIGNIFICANCE", "ELLIPSE_MIN_PX"]

logger = logging.getLogger(__name__)

#: Smallest outline radius searched, as a share of the photo's shorter side.
MIN_RADIUS_SHARE = 0.08
#: Largest outline radius searched, as a share of the photo's longer side.
MAX_RADIUS_SHARE = 0.75
#: Coarse candidates (the best of each octave, strongest first) refined and validated:
#: on the real photos of ``tests/data/real`` the mirror's octave was not always among
#: the three strongest coarse scores (texture in a sky, a building's windows).
CANDIDATES = 6
#: Shorter side (px) of the copy the candidates are compared on (larger photos are
#: reduced by an integer factor; the winner is refined at full resolution).
FREE_WORKING_SIDE_PX = 1024
#: Outline points of the circle template.
N_POINTS = 1440


def circle_outline(radius_px: float, n_points: int = N_POINTS) -> RimOutline:
    """A circle of ``radius_px`` about the axis as a :class:`RimOutline` at pitch 1 mm
    (so that its millimetres are pixels).

    Parameters
    ----------
    radius_px : float
        The circle's radius, px.
    n_points : int
        Points on the circle (evenly spaced in angle).
    """
    phi = np.linspace(0.0, 2.0 * math.pi, n_points, endpoint=False)
    unit = np.stack([np.cos(phi), np.sin(phi)], axis=-1)
    return RimOutline(uv=radius_px * unit, normal_uv=unit, sensor_distance=math.nan,
                      on_rim=np.ones(n_points, bool))


def find_circle(image: np.ndarray, *, radius_range_px: tuple[float, float] | None = None
                ) -> tuple[RimFit, float]:
    """The mirror's circular outline in a photo, without a setup.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        Linear photograph.
    radius_range_px : (float, float), optional
        Radii searched (default :data:`MIN_RADIUS_SHARE` of the shorter side to
        :data:`MAX_RADIUS_SHARE` of the longer one).

    Returns
    -------
    fit : RimFit
        ``center_px`` the circle's centre (row, col); ``scale`` times the returned
        radius' template, see ``radius_px``.
    radius_px : float
        The circle's radius.

    Raises
    ------
    mitsweep.photo.NoMirrorError
        No circle stands out as a mirror's outline.
    """
    lum = working_luminance(image, 32)
    H, W = lum.shape
    if radius_range_px is None:
        lo, hi = max(8.0, MIN_RADIUS_SHARE * min(H, W)), MAX_RADIUS_SHARE * max(H, W)
        if hi <= 2.0 * lo:
            raise NoMirrorError(f"no mirror found: the {W}x{H} px photo is too small to look "
                                f"for one (an outline of 8 px radius or more, at most "
                                f"{MAX_RADIUS_SHARE:.0%} of the longer side)")
    else:
        lo, hi = radius_range_px
        if not 8.0 <= lo < hi:
            raise ValueError(f"radius_range_px must satisfy 8 <= min < max, got {(lo, hi)}")
    void = photo_void(image)
    if void.any() and not void.all():
        lum = fill_void(lum, void)
    # The candidates are found and compared on a copy at most ~FREE_WORKING_SIDE_PX on its
    # shorter side; only the winner is refined at full resolution.
    f = max(1, min(H, W) // FREE_WORKING_SIDE_PX)
    if f == 1:
        return _best_circle(lum, image, lo, hi)
    small = reduce_by(lum, f)
    fit, radius = _best_circle(small, small, lo / f, hi / f)
    logger.info("free search at 1/%d: centre (%.1f, %.1f) px, radius %.1f px", f,
                fit.center_px[0] * f + (f - 1) / 2, fit.center_px[1] * f + (f - 1) / 2,
                radius * f)
    step = 1.0 + 2.0 / radius  # two reduced pixels' worth of scale
    # one start: the candidate is chosen already, at its own size
    fit = fit_rim(image, circle_outline(radius * f), 1.0, scale_range=(1.0 / step, step),
                  starts=1)
    return fit, radius * f * fit.scale


#: The outline is reported as an ellipse (a tilted view) where its semi-axes differ by
#: more than this many standard errors of the circle fit's centre (the same edge points
#: fix both, to about the same precision) and by more than :data:`ELLIPSE_MIN_PX`.
ELLIPSE_SIGNIFICANCE = 3.0
#: Smallest difference of the semi-axes (px) reported as an ellipse: the calibration's bar
#: for the centre (a noiseless drawn circle of radius 148 px reads 0.04 px, its sampling
#: on the pixel grid).
ELLIPSE_MIN_PX = 0.25


def ellipse_of_edges(fit: RimFit) -> dict | None:
    """The ellipse through a circle fit's edge points (scikit-image's direct
    least-squares ``EllipseModel``): what a circle leaves out where the camera does not
    look straight at an untilted mirror.

    Parameters
    ----------
    fit : RimFit
        A circle fit (:func:`find_circle`), its inliers' edge points
        (``edge_points_px``, row, col).

    Returns
    -------
    dict or None
        JSON-ready: ``center_px`` [row, col], ``semi_axes_px`` [major, minor],
        ``angle_deg`` (the major axis from the column axis, counter-clockwise as
        displayed, in [0, 180)),
        ``axis_ratio`` (minor / major), ``residual_rms_px`` (the points' distances from
        the ellipse) and ``significant`` (the semi-axes differ by more than
        :data:`ELLIPSE_SIGNIFICANCE` times the circle's centre standard error and more
        than :data:`ELLIPSE_MIN_PX`); None where fewer than 8 points or the fit fails.
    """
    from skimage.measure import EllipseModel

    pts = np.asarray(fit.edge_points_px, dtype=np.float64)
    if len(pts) < 8:
        return None
    xy = pts[:, ::-1]                      # x = column, y = row (down)
    if hasattr(EllipseModel, "from_estimate"):
        model = EllipseModel.from_estimate(xy)
        if not model:
            return None
        (xc, yc), (a, b), theta = model.center, model.axis_lengths, model.theta
    else:  # scikit-image < 0.26
        model = EllipseModel()
        if not model.estimate(xy):
            return None
        xc, yc, a, b, theta = model.params
    xc, yc, a, b, theta = (float(v) for v in (xc, yc, a, b, theta))
    if not all(math.isfinite(v) for v in (xc, yc, a, b, theta)) or min(a, b) <= 0:
        return None
    if b > a:
        a, b, theta = b, a, theta + math.pi / 2
    # theta turns x toward y (down): clockwise as displayed
    angle = math.degrees(-theta) % 180.0
    rms = float(np.sqrt(np.mean(model.residuals(xy) ** 2)))
    se = fit.center_se_px if math.isfinite(fit.center_se_px) else math.inf
    return {"center_px": [yc, xc], "semi_axes_px": [a, b], "angle_deg": angle,
            "axis_ratio": b / a, "residual_rms_px": rms,
            "significant": bool(a - b > max(ELLIPSE_SIGNIFICANCE * se, ELLIPSE_MIN_PX))}


def _best_circle(lum: np.ndarray, image: np.ndarray, lo: float, hi: float
                 ) -> tuple[RimFit, float]:
    """Coarse candidates per octave of radius in ``[lo, hi]`` (searched on ``lum``), each
    refined and validated on ``image``; the best explained one."""
    candidates = []
    base = lo * math.sqrt(2.0)
    while base / math.sqrt(2.0) < hi:
        template = circle_outline(base, n_points=360)
        pts, nrm = template.offsets_px(1.0)
        scales = search_scales(1.0 / math.sqrt(2.0), min(math.sqrt(2.0), hi / base))
        centre, scale, score = coarse_search(lum, pts, nrm, scales)
        candidates.append((score, centre, base * scale))
        base *= 2.0
    candidates.sort(key=lambda c: -c[0])
    best, failures = None, []
    for score, centre, radius in candidates[:CANDIDATES]:
        logger.info("free search candidate: centre (%.1f, %.1f) px, radius %.1f px "
                    "(score %.3g)", *centre, radius, score)
        try:
            fit = fit_rim(image, circle_outline(radius), 1.0, scale_range=(0.96, 1.04),
                          starts=1)   # this search compares its candidates itself
        except CalibrationError as exc:
            failures.append(str(exc))
            continue
        # the outline explained best: most points, least scatter relative to its size
        key = (fit.points_used / fit.points_total) * radius / max(fit.residual_rms_px, 0.1)
        if best is None or key > best[0]:
            best = (key, fit, radius * fit.scale)
    if best is None:
        raise NoMirrorError(f"no mirror found: no circle of radius {lo:.0f}-{hi:.0f} px "
                            f"stands out as a mirror's outline (the strongest candidate: "
                            f"{failures[0].removeprefix('no mirror found: ')})")
    return best[1], best[2]
