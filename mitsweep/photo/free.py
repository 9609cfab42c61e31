"""Find a mirror's outline in a photo without a setup: :func:`find_circle`.

Where no setup exists yet (a new camera, an unknown mirror), the outline is taken to be
a circle, the image of an untilted mirror's rim or limb, of unknown centre and radius.
The coarse search (:mod:`mitsweep.photo.coarse`) runs once per octave of radius, from
:data:`MIN_RADIUS_SHARE` of the photo's shorter side to :data:`MAX_RADIUS_SHARE` of its
longer one (a rim clipped by the frame is larger than the frame), each on a copy reduced
for that octave; the strongest candidates are refined and validated as a setup's
outline is (:func:`mitsweep.photo.rim.fit_rim`), and the validated one whose edge stands
out most from its surroundings is kept. Where none is accepted at its own size (a
candidate can be a ring inside the mirror's image), each is searched again as a rough
setup's prediction would be (:data:`WIDE_LOOK`, several starts). Without a setup nothing
says where a mirror is, so a circle (or an ellipse, below) is accepted only where the fit
uses most of the outline the photo shows (:data:`FREE_MIN_SUPPORT`; a circle along a
brick wall's mortar is not).

A camera that does not look straight at an untilted mirror sees its outline as an
ellipse; up to a tilt of about 9 degrees a circle still explains it (and
:func:`ellipse_of_edges` reports the ellipse through the circle's edge points). Where no
circle is accepted, the strongest candidates are looked at again as ellipses: the
strongest edge along each normal of the candidate's circle, within a window wide enough
for an axis ratio of :data:`MIN_AXIS_RATIO`, gives points that a RANSAC ellipse
(scikit-image) turns into an elliptical outline, which is refined and validated as any
outline is; the ellipse through the refined edge points then reshapes the outline, for at
most :data:`ELLIPSE_ROUNDS` rounds.

A sphere's outline is its limb, where a photo may show no edge that stands out (the
reflection there continues what lies behind the mirror). Where neither a circle nor an
ellipse is accepted, each candidate is looked at last as a limb
(:func:`mitsweep.photo.limb.fit_limb`, over the :data:`WIDE_LOOK` scales): found from how
the image changes across it, and only where the detail just inside it runs along it, as
a reflection squeezed at a limb does. The fit's ``limb`` says which it is.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from ..optics.outline import RimOutline
from .coarse import MAX_CANDIDATES, coarse_search, search_scales
from .image import fill_void, photo_void, reduce_by
from .rim import (PLAUSIBLE_SCALE, CalibrationError, NoMirrorError, RimFit, fit_rim,
                  WORKING_SIDE_PX, refine_at_full_resolution, rim_fit_of_limb, settled,
                  working_factor, working_luminance)

__all__ = ["find_circle", "circle_outline", "ellipse_outline", "ellipse_of_edges",
           "MIN_RADIUS_SHARE", "MAX_RADIUS_SHARE", "CANDIDATES", "FREE_LIMB_RADIAL_SHARE",
           "FREE_MIN_SUPPORT", "visible_support",
           "ELLIPSE_SIGNIFICANCE", "ELLIPSE_MIN_PX", "MIN_AXIS_RATIO", "WIDE_LOOK",
           "ELLIPSE_ROUNDS", "ELLIPSE_TRIALS"]

logger = logging.getLogger(__name__)

#: Scales (relative to a coarse candidate's radius) of the second look, where no candidate
#: is accepted at its own size: the range a rough setup's prediction is searched over
#: (:data:`mitsweep.photo.rim.PLAUSIBLE_SCALE`).
WIDE_LOOK = (1.0 / (1.0 + PLAUSIBLE_SCALE), 1.0 / (1.0 - PLAUSIBLE_SCALE))

#: Without a setup nothing says a sphere is there: a limb is accepted only where the
#: detail just inside it runs along it in every one of the
#: :data:`mitsweep.photo.limb.RADIAL_SECTORS` sectors (a setup's limb fit asks for
#: :data:`mitsweep.photo.limb.MIN_RADIAL_SHARE`). Measured on the limbs that fit found
#: (renders of the sphere 200-400 px, the real chrome balls, PAGEOS and the dome: 28 of
#: 30 read 1, sphere_tokyo's two 0.83, and its edge is found as a circle) and on circles
#: in photos without a mirror (0.25-1: 2 of 28 read 1, both the astronaut portrait's
#: circle, which ``--free`` finds as an edge anyway; the Kodak photo's 0.83).
FREE_LIMB_RADIAL_SHARE = 1.0
#: Without a setup nothing says where a mirror is, so a circle or an ellipse is taken for
#: its outline only where the fit uses at least this share of the outline's points that
#: the photo shows (in the frame, not in a render's void); a setup's fit asks for
#: :data:`mitsweep.photo.rim.MIN_INLIER_FRACTION` of all of them. Measured
#: (``scripts/free_support.py``): the circles and the ellipse found in the photos of
#: mirrors in ``tests/data/real`` 0.83-1.00 (a lamp's holder, a mount; the rim cut by the
#: frame 0.95 of what the frame shows); the circles ``--free`` took in scikit-image's
#: sample photos without a mirror: a brick wall's 0.70 (now refused), and round things
#: fitted all round (a coin, a crater, a cup's rim: 0.98-1.00) or nearly (a circle cut by
#: the frame in the astronaut portrait, 0.85), still taken. A mirror whose holder hides
#: more of its outline is calibrated with a setup.
FREE_MIN_SUPPORT = 0.75
#: Smallest outline radius searched, as a share of the photo's shorter side.
MIN_RADIUS_SHARE = 0.08
#: Largest outline radius searched, as a share of the photo's longer side.
MAX_RADIUS_SHARE = 0.75
#: Coarse candidates (the best of each octave, strongest first) refined and validated:
#: on the real photos of ``tests/data/real`` the mirror's octave was not always among
#: the three strongest coarse scores (texture in a sky, a building's windows).
CANDIDATES = 6
#: Shorter side (px) of the copy the candidates are compared on (larger photos are
#: reduced by an integer factor; the winner is refined at full resolution): the setup
#: path's :data:`mitsweep.photo.rim.WORKING_SIDE_PX`.
FREE_WORKING_SIDE_PX = WORKING_SIDE_PX
#: Outline points of the circle template.
N_POINTS = 1440
#: Smallest minor-to-major axis ratio the ellipse search allows for (a view tilted by up
#: to ~45 degrees): it sets the window searched for edges around a candidate circle.
MIN_AXIS_RATIO = 0.7
#: Rounds of reshaping an elliptical outline (fit, ellipse through its edge points) at most.
ELLIPSE_ROUNDS = 4
#: An elliptical outline has settled when a round moves its centre and semi-axes by less
#: than this, px.
ELLIPSE_SETTLED_PX = 0.02


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


def ellipse_outline(a_px: float, b_px: float, angle_deg: float,
                    n_points: int = N_POINTS) -> RimOutline:
    """An ellipse about the axis as a :class:`RimOutline` at pitch 1 mm: semi-axes
    ``a_px`` and ``b_px``, the first at ``angle_deg`` from the column axis,
    counter-clockwise as displayed (:func:`ellipse_of_edges`' convention).

    Parameters
    ----------
    a_px, b_px : float
        The semi-axes, px.
    angle_deg : float
        The direction of the ``a_px`` axis, degrees.
    n_points : int
        Points on the ellipse (evenly spaced in its parameter).
    """
    t = np.linspace(0.0, 2.0 * math.pi, n_points, endpoint=False)
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    rot = np.array([[c, -s], [s, c]])           # u right, v up: counter-clockwise
    uv = np.stack([a_px * np.cos(t), b_px * np.sin(t)], axis=-1) @ rot.T
    nrm = np.stack([np.cos(t) / a_px, np.sin(t) / b_px], axis=-1)
    nrm = (nrm / np.linalg.norm(nrm, axis=1, keepdims=True)) @ rot.T
    return RimOutline(uv=uv, normal_uv=nrm, sensor_distance=math.nan,
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
        radius' template, see ``radius_px``. Where the outline was found as an ellipse
        (see the module docstring), its centre, and :func:`ellipse_of_edges` gives its
        axes.
    radius_px : float
        The circle's radius (an ellipse's: the radius of the circle of its area).

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
    # The candidates are found and compared on a copy of ~FREE_WORKING_SIDE_PX (0.75-1.5
    # times) on its shorter side; only the winner is refined at full resolution.
    f = working_factor((H, W))
    if f == 1:
        fit, radius, shape = _best_circle(lum, image, lo, hi)
        return fit, radius
    small = reduce_by(lum, f)
    fit, radius, shape = _best_circle(small, small, lo / f, hi / f)
    logger.info("free search at 1/%d: centre (%.1f, %.1f) px, radius %.1f px", f,
                fit.center_px[0] * f + (f - 1) / 2, fit.center_px[1] * f + (f - 1) / 2,
                radius * f)
    if shape is not None:   # an ellipse: its axes at full resolution, reshaped there
        a, b, angle = shape
        fit = _reshaped_ellipse(image, (a * f, b * f, angle))
        return fit, _equivalent_radius(fit)
    step = 1.0 + 2.0 / radius  # two reduced pixels' worth of scale
    if fit.limb:   # a limb: fitted again at full resolution, from the reduced copy's
        centre = (fit.center_px[0] * f + (f - 1) / 2, fit.center_px[1] * f + (f - 1) / 2)
        found = _limb_at(lum, _shown(image), centre, radius * f, (1.0 / step, step),
                         stride=f)
        if found is None:
            raise NoMirrorError(f"no mirror found: a sphere's limb found on the photo "
                                f"reduced {f}x (centre row {centre[0]:.1f}, col "
                                f"{centre[1]:.1f}, radius {radius * f:.1f} px) is not "
                                f"found again at full resolution")
        return found
    # the candidate is chosen and fitted already: refined at full resolution near it
    template_px = radius * f / fit.scale   # the circle it was fitted to, scaled by f
    fit = refine_at_full_resolution(image, circle_outline(template_px), 1.0, fit, f)
    return fit, template_px * fit.scale


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
    pts = np.asarray(fit.edge_points_px, dtype=np.float64)
    if len(pts) < 8:
        return None
    params = _ellipse_params(pts[:, ::-1])     # x = column, y = row (down)
    if params is None:
        return None
    xc, yc, a, b, angle, rms = params
    se = fit.center_se_px if math.isfinite(fit.center_se_px) else math.inf
    return {"center_px": [yc, xc], "semi_axes_px": [a, b], "angle_deg": angle,
            "axis_ratio": b / a, "residual_rms_px": rms,
            "significant": bool(a - b > max(ELLIPSE_SIGNIFICANCE * se, ELLIPSE_MIN_PX))}


def _best_circle(lum: np.ndarray, image: np.ndarray, lo: float, hi: float
                 ) -> tuple[RimFit, float, tuple[float, float, float] | None]:
    """Coarse candidates per octave of radius in ``[lo, hi]`` (searched on ``lum``), each
    refined and validated on ``image``; the best explained one, as ``(fit, radius,
    None)``, or, where no circle is accepted, the best ellipse (:func:`_best_ellipse`:
    ``(fit, radius, (a, b, angle_deg))``)."""
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
    failures: list[str] = []
    weak: list[str] = []    # outlines fitted but refused for their support: said first
    # First each candidate at its own size, one start (this search compares its
    # candidates itself); where none is accepted, a second look at each as a rough
    # setup's prediction is searched (a coarse candidate can be a ring inside the mirror's
    # image, a tenth smaller than its outline: omni_kaidan.jpg in tests/data/real).
    for scale_range, starts in (((0.96, 1.04), 1), (WIDE_LOOK, MAX_CANDIDATES)):
        best = None
        for score, centre, radius in candidates[:CANDIDATES]:
            logger.info("free search candidate: centre (%.1f, %.1f) px, radius %.1f px "
                        "(score %.3g), scales %.2f-%.2f", *centre, radius, score,
                        *scale_range)
            outline = circle_outline(radius)
            try:
                fit = fit_rim(image, outline, 1.0, scale_range=scale_range, starts=starts)
            except CalibrationError as exc:
                failures.append(str(exc))
                continue
            why = _weakly_supported(fit, outline, image)
            if why:
                weak.append(why)
                continue
            # the outline explained best: most points, least scatter relative to its size
            size = radius * fit.scale
            key = _explained(fit, size)
            if best is None or key > best[0]:
                best = (key, fit, size)
        if best is not None:
            return best[1], best[2], None
    found = _best_ellipse(lum, image, candidates[:CANDIDATES])
    if found is not None:
        return found
    shown = _shown(image)
    looks = (_limb_at(lum, shown, centre, radius, WIDE_LOOK)
             for _score, centre, radius in candidates[:CANDIDATES])
    limbs = [fr for fr in looks if fr is not None]
    if limbs:
        fit, radius = max(limbs, key=lambda fr: _explained(fr[0], fr[1]))
        return fit, radius, None
    # the fits' messages speak to a setup's user; here there is none
    nearest = (f"a circle: {weak[0].removeprefix('no mirror found: ')}" if weak else
               "the strongest candidate: " + failures[0].removeprefix("no mirror found: ")
               .removesuffix(_SETUP_HINT))
    raise NoMirrorError(f"no mirror found: no circle of radius {lo:.0f}-{hi:.0f} px "
                        f"stands out as a mirror's outline, nor an ellipse of axis ratio "
                        f"{MIN_AXIS_RATIO:g} or more, nor a sphere's limb ({nearest})")


def visible_support(fit: RimFit, outline: RimOutline, image: np.ndarray) -> float:
    """The share of an outline's points that the photo shows (in its frame, not in a
    render's void) which a fit used: what :data:`FREE_MIN_SUPPORT` is judged on.

    Parameters
    ----------
    fit : RimFit
        A fit of ``outline`` (its ``center_px``, ``scale`` and ``points_used``).
    outline : RimOutline
        The outline fitted, in pixels (pixel pitch 1, as :func:`circle_outline` makes it).
    image : (H, W) or (H, W, C) ndarray
        The photo it was fitted on.

    Returns
    -------
    float
        ``points_used`` over the points shown; 0 where none is.
    """
    pts, _nrm = outline.offsets_px(1.0)
    at = np.rint(np.asarray(fit.center_px)[None, :] + fit.scale * pts).astype(np.int64)
    H, W = np.shape(image)[:2]
    inside = (at[:, 0] >= 0) & (at[:, 0] < H) & (at[:, 1] >= 0) & (at[:, 1] < W)
    shown = _shown(image)
    if shown is not None:
        inside[inside] = shown[at[inside, 0], at[inside, 1]]
    n = int(inside.sum())
    return fit.points_used / n if n else 0.0


def _weakly_supported(fit: RimFit, outline: RimOutline, image: np.ndarray) -> str | None:
    """Why a circle or an ellipse fitted without a setup is not taken for a mirror's
    outline (:data:`FREE_MIN_SUPPORT`), or None where it is supported."""
    support = visible_support(fit, outline, image)
    if support >= FREE_MIN_SUPPORT:
        return None
    return (f"no mirror found: an outline at row {fit.center_px[0]:.1f}, col "
            f"{fit.center_px[1]:.1f} is fitted to {support:.0%} of its points the photo "
            f"shows; without a setup {FREE_MIN_SUPPORT:.0%} are needed (a mirror whose "
            f"holder hides more of its outline is calibrated with --setup)")


#: How the setup path's refusals end (:func:`mitsweep.photo.rim.fit_rim`): left out of
#: ``--free``'s, which has no setup.
_SETUP_HINT = "; check that the photo shows the mirror of this setup"


def _explained(fit: RimFit, size: float) -> float:
    """How well a fit explains its outline: the share of its points used, times its size
    over its scatter (the key the candidates are compared by)."""
    return (fit.points_used / fit.points_total) * size / max(fit.residual_rms_px, 0.1)


def _shown(image: np.ndarray) -> np.ndarray | None:
    """The pixels a photo shows (None where it shows all, or none)."""
    void = photo_void(image)
    return ~void if void.any() and not void.all() else None


def _limb_at(lum: np.ndarray, shown: np.ndarray | None, centre: tuple[float, float],
             radius: float, scale_range: tuple[float, float], stride: int = 1
             ) -> tuple[RimFit, float] | None:
    """A sphere's limb near the circle ``centre``, ``radius`` (px), its size within
    ``scale_range`` times it (:func:`mitsweep.photo.limb.fit_limb`, where the photo shows
    no edge that stands out: the PAGEOS balloon in ``tests/data/real``), as ``(fit,
    radius_px)``; None where none is found. ``stride``: see
    :func:`mitsweep.photo.limb.fit_limb` (the refinement of a limb found on a reduced copy)."""
    from .limb import fit_limb

    pts, nrm = circle_outline(radius).offsets_px(1.0)
    limb = fit_limb(lum, centre, pts, nrm, scale_range, shown=shown, near_px=radius,
                    stride=stride)
    if limb is None or limb.radial_share < FREE_LIMB_RADIAL_SHARE:
        return None
    logger.info("free search: limb at (%.1f, %.1f) px, radius %.1f px (radial share %.2f)",
                *limb.center_px, limb.radius_px, limb.radial_share)
    return rim_fit_of_limb(limb, pts, nrm, radius), limb.radius_px


def _equivalent_radius(fit: RimFit) -> float:
    """The radius of the circle of the area of a fit's elliptical outline."""
    e = ellipse_of_edges(fit)
    return math.sqrt(e["semi_axes_px"][0] * e["semi_axes_px"][1]) if e else math.nan


def _best_ellipse(lum: np.ndarray, image: np.ndarray, candidates: list
                  ) -> tuple[RimFit, float, tuple[float, float, float]] | None:
    """The coarse candidates looked at again as ellipses (see the module docstring): the
    best explained validated one, as ``(fit, radius, (a, b, angle_deg))``, or None."""
    from .edges import edge_offsets
    from .image import smooth
    from .rim import PROFILE_SMOOTHING_PX

    lum_s = smooth(lum, PROFILE_SMOOTHING_PX)
    best = None
    for _score, centre, radius in candidates:
        pts, nrm = circle_outline(radius, n_points=720).offsets_px(1.0)
        half = (1.0 - MIN_AXIS_RATIO) * radius + 2.0
        off, _strength, _width = edge_offsets(lum_s, centre, 1.0, pts, nrm, half)
        ok = np.isfinite(off)
        if ok.sum() < 20:
            continue
        edges = np.asarray(centre)[None, :] + pts[ok] + off[ok, None] * nrm[ok]
        start = _ransac_ellipse(edges, threshold=max(1.5, 0.01 * radius))
        if start is None:
            continue
        (row, col), a, b, angle = start
        if b < MIN_AXIS_RATIO * a:
            continue
        try:
            fit = _reshaped_ellipse(image, (a, b, angle))
        except CalibrationError as exc:
            logger.info("ellipse candidate (%.1f, %.1f) px, axes %.1f x %.1f px refused: %s",
                        row, col, a, b, exc)
            continue
        e = ellipse_of_edges(fit)
        if e is None:
            continue
        a, b = e["semi_axes_px"]
        why = _weakly_supported(fit, ellipse_outline(a, b, e["angle_deg"]), image)
        if why:
            logger.info("ellipse candidate (%.1f, %.1f) px refused: %s", row, col, why)
            continue
        key = (fit.points_used / fit.points_total) * math.sqrt(a * b) \
            / max(fit.residual_rms_px, 0.1)
        if best is None or key > best[0]:
            best = (key, fit, math.sqrt(a * b), (a, b, e["angle_deg"]))
        if settled(fit):   # explains its edges so well that no other candidate is looked at
            break
    return None if best is None else best[1:]


def _reshaped_ellipse(image: np.ndarray, shape: tuple[float, float, float]) -> RimFit:
    """An elliptical outline of ``shape`` (a, b, angle_deg) refined and validated
    (:func:`mitsweep.photo.rim.fit_rim`), reshaped to the ellipse through its edge points
    until it settles (:data:`ELLIPSE_ROUNDS`, :data:`ELLIPSE_SETTLED_PX`)."""
    a, b, angle = shape
    fit, before = None, None
    for _ in range(ELLIPSE_ROUNDS):
        fit = fit_rim(image, ellipse_outline(a, b, angle), 1.0, scale_range=(0.97, 1.03),
                      starts=1)
        e = ellipse_of_edges(fit)
        if e is None:
            break
        now = np.array([*e["center_px"], *e["semi_axes_px"]])
        a, b = e["semi_axes_px"]
        angle = e["angle_deg"]
        if before is not None and np.abs(now - before).max() < ELLIPSE_SETTLED_PX:
            break
        before = now
    assert fit is not None
    return fit


#: RANSAC draws of five edge points for an ellipse (fixed seed).
ELLIPSE_TRIALS = 400


def _conic_distance(conic: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """First-order (Sampson) distance of points from the conic ``A x^2 + B xy + C y^2 +
    D x + E y + F = 0``: its value over its gradient's length."""
    x, y = xy[:, 0], xy[:, 1]
    A, B, C, D, E, F = conic
    q = A * x * x + B * x * y + C * y * y + D * x + E * y + F
    gx, gy = 2 * A * x + B * y + D, B * x + 2 * C * y + E
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.abs(q) / np.hypot(gx, gy)


def _ransac_ellipse(points_rc: np.ndarray, threshold: float
                    ) -> tuple[tuple[float, float], float, float, float] | None:
    """A RANSAC ellipse through edge points (row, col): conics through 5 points drawn at
    random (:data:`ELLIPSE_TRIALS`, fixed seed), scored by the points within
    ``threshold`` px (first-order distance), the best refitted on its inliers by
    scikit-image's direct least squares: ``((row, col), a, b, angle_deg)``, ``a >= b``;
    None where no ellipse has 20 inliers. Not ``skimage.measure.ransac``: it scores each
    draw with ``EllipseModel.residuals``, an optimisation per point (46 of 60 s of a
    search on a 400-px photo)."""
    xy = points_rc[:, ::-1].astype(np.float64)
    mu, sd = xy.mean(axis=0), float(xy.std()) or 1.0
    z = (xy - mu) / sd                      # conditioned
    design = np.column_stack([z[:, 0] ** 2, z[:, 0] * z[:, 1], z[:, 1] ** 2, z[:, 0], z[:, 1],
                              np.ones(len(z))])
    rng = np.random.default_rng(0)
    best, best_n = None, 0
    for _ in range(ELLIPSE_TRIALS):
        pick = rng.choice(len(z), 5, replace=False)
        conic = np.linalg.svd(design[pick])[2][-1]
        if conic[1] ** 2 - 4.0 * conic[0] * conic[2] >= 0:    # not an ellipse
            continue
        inl = _conic_distance(conic, z) * sd < threshold
        n = int(inl.sum())
        if n > best_n:
            best, best_n = inl, n
    if best is None or best_n < 20:
        return None
    params = _ellipse_params(xy[best])
    if params is None:
        return None
    xc, yc, a, b, angle, _rms = params
    return (yc, xc), a, b, angle


def _ellipse_params(xy: np.ndarray) -> tuple[float, float, float, float, float, float] | None:
    """The direct least-squares ellipse through (x = col, y = row) points: ``(xc, yc, a,
    b, angle_deg, rms)``, ``a >= b``, the angle of ``a`` counter-clockwise as displayed
    in [0, 180); None where the fit fails."""
    from skimage.measure import EllipseModel

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
    # the points' distances from the ellipse, to first order (scikit-image's exact
    # residuals solve a small optimisation per point: 0.4 s for 1440 points)
    ct, st = math.cos(theta), math.sin(theta)
    u = (xy[:, 0] - xc) * ct + (xy[:, 1] - yc) * st     # along a
    v = -(xy[:, 0] - xc) * st + (xy[:, 1] - yc) * ct    # along b
    q = (u / a) ** 2 + (v / b) ** 2 - 1.0
    grad = 2.0 * np.hypot(u / a ** 2, v / b ** 2)
    rms = float(np.sqrt(np.mean((q / grad) ** 2)))
    # theta turns x toward y (down): clockwise as displayed
    return xc, yc, a, b, math.degrees(-theta) % 180.0, rms
