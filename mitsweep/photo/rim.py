"""Find the setup's predicted outline in a photograph: :func:`fit_rim`.

The unknowns are where the axis is (``center_px``, row and column) and a scale ``k`` of
the outline about it, which absorbs a wrong pixel pitch or lens–mirror distance; the
camera's roll about its axis can be a fourth where the outline shows it (a tilted
mirror's; ``fit_roll``). Three steps:

1. *Coarse* (:mod:`mitsweep.photo.coarse`): position and scale by correlating
   orientation fields with the outline's normals on a reduced copy. (A photo from 1.5
   times :data:`WORKING_SIDE_PX` on its shorter side goes through all three steps on a
   copy reduced by a whole factor, then :func:`refine_at_full_resolution`.)
2. *Refine* (:mod:`mitsweep.photo.edges`): at full resolution, a sub-pixel edge along the
   outline's normal at each of N points; the normal offsets fitted by iteratively
   reweighted least squares (Tukey's biweight, :func:`mitsweep.photo.robust.tukey_lstsq`),
   so that edges of a mount, an arm crossing the rim or a reflection do not pull the fit.
   Vignetting and smooth illumination changes do not move a gradient's peak.
3. *Validate*: enough of the outline must show an edge, the outline must stand out
   from its surroundings (:func:`mitsweep.photo.edges.edge_prominence`) and the edges
   must lie on it within :data:`MAX_RESIDUAL_RMS_PX`; otherwise :class:`CalibrationError`
   says which test failed. The centre's standard error is reported.

A setup that is only roughly right (a guessed pitch or distance, ±35%) leaves other
outlines near the predicted one: a mount's inner edge, a concentric edge of the
reflection. Steps 2 and 3 therefore run from each of the coarse search's starting points
(:func:`mitsweep.photo.coarse.coarse_candidates`, the first being the outline nearest the
prediction), twice: once from each normal's strongest edge, once from the outline that
most normals show *an* edge on (RANSAC over the edges,
:func:`mitsweep.photo.robust.consensus_lstsq`), which finds a dim stretch of rim beside a
strong edge of the reflection. Of the fits validated, the first is kept unless another
explains edges markedly better (:func:`fit_support`, :data:`CLEARLY_BETTER`).

What the photo does not show is left out: exact zeros (what a renderer skipped,
:func:`mitsweep.photo.image.photo_void`) are filled from the nearest shown pixel, so the
border of a render cropped to the mirror's window is no edge, and outline points there
are not asked for one.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator
from dataclasses import dataclass, field, replace

import numpy as np

from ..optics.outline import RimOutline
from ..deprecation import renamed_keywords
from ..resources import check_allocation
from .coarse import (COARSE_RADIUS_PX, COARSE_SCALE_STEP, MAX_CANDIDATES, coarse_candidates,
                     coarse_search, search_scales)
from .edges import edge_candidates, edge_offsets, edge_prominence
from .image import fill_void, luminance, noise_sigma, photo_void, reduce_by, smooth
from .limb import LimbFit
from .robust import (EDGE_CORRELATION_PX, centre_standard_error, consensus_lstsq,
                     tukey_lstsq)

__all__ = ["CalibrationError", "NoMirrorError", "SetupMismatchError", "RimFit", "fit_rim",
           "rim_fit_of_limb", "refine_at_full_resolution", "working_factor",
           "working_luminance", "WORKING_SIDE_PX",
           "REFINE_WINDOW_REDUCED_PX", "REFINE_SMOOTHING_GROWS", "MIN_INLIER_FRACTION",
           "MIN_CONSISTENT_FRACTION",
           "MIN_EDGE_PROMINENCE", "MAX_RESIDUAL_RMS_PX",
           "RESIDUAL_WIDTH_SHARE", "RESIDUAL_RADIUS_SHARE", "PLAUSIBLE_SCALE",
           "PROFILE_SMOOTHING_PX", "MAX_EDGE_SNR", "ROLL_OBSERVABLE", "LIMB_INSIDE_SHARE",
           "MAX_LIMB_COHERENCE", "CONSENSUS_EDGES", "CONSENSUS_TOLERANCE_PX",
           "CLEARLY_BETTER", "SUPPORT_RMS_FLOOR_PX", "SETTLED_SHARE", "SETTLED_RMS_PX",
           "START_PASSES", "CONCENTRIC_STARTS",
           "fit_edges", "fit_support", "choose_fit", "unbeatable", "settled"]

logger = logging.getLogger(__name__)

#: Largest relative difference between the measured and the predicted outline size
#: that the search covers and a calibration accepts (with a warning beyond
#: :data:`mitsweep.photo.calibrate.WARN_SCALE`): a guessed lens–mirror distance or an
#: unknown pixel pitch, what a user has before calibrating.
PLAUSIBLE_SCALE = 0.35
#: Smallest share of the outline points the photo shows that must show an edge.
MIN_INLIER_FRACTION = 0.4
#: Smallest share of those edges that the fitted outline must explain (the robust fit's
#: inliers): on the faint rim of a rendered tilted paraboloid (200 px, 64 spp) 45% of the
#: outline shows an edge above the noise, and 86% of those edges are inliers.
MIN_CONSISTENT_FRACTION = 0.6
#: Smallest ratio of the gradient on the fitted outline to the gradient beside it
#: (:func:`edge_prominence`): a mirror's rim stands out, texture does not.
MIN_EDGE_PROMINENCE = 3.0
#: Gaussian smoothing (px) of the image the edge profiles are sampled on: it lowers
#: the noise; on a rim of radius R it moves the edge inward by only ~σ²/(2R).
PROFILE_SMOOTHING_PX = 1.2
#: Edge contrast-to-noise ratio above which edges count as equally precise (the
#: limit is then the texture, not the noise).
MAX_EDGE_SNR = 30.0
#: Largest RMS normal residual (px) of the inliers of an accepted fit: an outline of
#: the wrong shape (the square border of a render cropped to the mirror's window, found
#: at +7..17% of the rim's size) leaves 1.8-2.0 px on the renders, the true rim of the
#: rendered tilted paraboloid 0.65-0.95 px (its weak edges scatter against the detailed
#: reflection).
MAX_RESIDUAL_RMS_PX = 1.5
#: Share of the edges' measured width (the median RMS width of their derivative lobes)
#: that the residual RMS may reach where that exceeds :data:`MAX_RESIDUAL_RMS_PX`: an
#: edge is placed to a fraction of its width, so a soft edge (a large photo's
#: demosaicked, compressed rim, a limb's fall-off) is judged relative to its width, and a
#: sharp one (a render's) by the absolute floor.
RESIDUAL_WIDTH_SHARE = 0.5
#: Share of the outline's radius that the residual RMS may reach where that exceeds the
#: two floors above: a real mirror's outline departs from the model by a fraction of its
#: size (a slightly tilted or decentred mirror, lens distortion). Measured on the real
#: photos of ``tests/data/real`` with circles: 0.1-1.2% of the radius. The square border
#: of a cropped render (the wrong shape, 1.8-2.0 px at 80 px) stays refused.
RESIDUAL_RADIUS_SHARE = 0.012
#: Shorter side (px) of the copy a photo is searched on: from 1.5 times it, a photo is
#: reduced by the whole factor nearest its shorter side over this (:func:`working_factor`,
#: :func:`fit_rim`), to 0.75-1.5 times it: the search's windows and
#: thresholds were set on photos and renders of 200-1232 px, and an outline on a larger
#: photo is the same outline with wider edges and more of its texture. The outline found
#: there is refined at full resolution (:func:`refine_at_full_resolution`).
WORKING_SIDE_PX = 1024
#: Half-width of the full-resolution refinement's window, in reduced pixels.
REFINE_WINDOW_REDUCED_PX = 2.0
#: Whether the full-resolution refinement smooths the edge profiles by
#: :data:`PROFILE_SMOOTHING_PX` times the reduction (True), so that the edge refined is
#: the one found at the working size, at that size's scale, or by
#: :data:`PROFILE_SMOOTHING_PX` (False). ``scripts/bench_large_photos.py --paths reduced
#: fixed-smoothing`` runs both side by side; docs/reference/photos.md gives the enlarged
#: chrome balls' figures, which tests/test_calibrate_large.py measures.
REFINE_SMOOTHING_GROWS = True
#: Whether a first fit that did not :func:`settle <settled>` is followed by starts about
#: its centre at the coarse starts' other scales, each from the outline most normals
#: show an edge on within two coarse scale steps (True), or not (False): a mirror's rim
#: and its mount are concentric, and the coarse search's centres can be tens of pixels
#: off. ``scripts/bench_large_photos.py --paths reduced no-concentric`` runs both side by
#: side; tests/test_calibrate_large.py holds the enlarged photo it was made for.
CONCENTRIC_STARTS = True
#: Peak working memory of a calibration, bytes per photo pixel (the photo itself not
#: counted): float64 luminance, its smoothed and void-filled copies, the coarse cues.
#: Measured: 27 (a setup) and 38 (--free) on a 24 MP JPEG.
WORK_BYTES_PER_PIXEL = 40.0
#: The refinement stops once a pass moves the outline by less than this share of the
#: centre's standard error (or by less than 1e-3 px).
STEP_SHARE_OF_SE = 0.05
#: The roll is fitted when a radian of it moves the outline's points by more than this
#: share of its radius (RMS along the normals): never for a circle about the axis
#: (0), for the tilted paraboloid 0.30.
ROLL_OBSERVABLE = 0.01
#: A limb outline's edge fit that lands more than this share of the radius inside the
#: limb the limb fit finds is an edge of the reflection, not the outline
#: (:func:`fit_rim`): on renders of scenes/sphere.toml the room's boards end 14% inside
#: the limb; on the real chrome balls of tests/data/real the edge fit is the limb (a
#: dark line), and the limb fit (made for renders) lands 0.0-1.3% outside it.
LIMB_INSIDE_SHARE = 0.05
#: Largest coherence of the sign of the mean's step across a limb the limb fit finds
#: (:func:`mitsweep.photo.limb._step_coherence`) for it to replace an edge fit: a limb's
#: step has the sign of the local background against its far average (0.00-0.26 on the
#: full sphere renders, 0.40 where the frame crops 12% of the radius off the limb),
#: an edge one sign all round (a holder's dark ring 8 px outside the synthetic sphere's
#: rim: 0.87; the dark line of the real sphere_lamp: 0.83).
MAX_LIMB_COHERENCE = 0.6
#: Edges per normal offered to the consensus start (:func:`_consensus_start`).
CONSENSUS_EDGES = 4
#: A normal agrees with a consensus outline when one of its edges lies within this
#: (px), or half of :data:`RESIDUAL_RADIUS_SHARE` of the radius where that is more.
CONSENSUS_TOLERANCE_PX = 1.5
#: Of the fits refined from several starting points, the best supported
#: (:func:`fit_support`) replaces the coarse search's own where its support is this many
#: times larger (:func:`choose_fit`); otherwise the outline nearest the prediction is kept.
CLEARLY_BETTER = 1.25
#: Residual RMS (px) below which a fit counts as exact in :func:`fit_support`: edges are
#: placed to ~0.1-0.3 px, so tighter residuals say nothing more of which outline it is.
SUPPORT_RMS_FLOOR_PX = 0.25
#: A first fit explaining this share of the outline's points within
#: :data:`SETTLED_RMS_PX` is kept without refining the other starting points
#: (:func:`settled`).
SETTLED_SHARE = 0.9
#: See :data:`SETTLED_SHARE` (px).
SETTLED_RMS_PX = 0.5
#: Passes within which a refinement other than the first (the outline nearest the
#: prediction, from its strongest edges) must converge to count: one that keeps moving
#: is wandering between outlines (a mount's edge and a rim that is no circle; the rims
#: of the real photos converge in 5-14 passes, the renders' in 3-5).
START_PASSES = 15


class CalibrationError(ValueError):
    """The mirror was not found in the photo, or disagrees with the setup."""


class NoMirrorError(CalibrationError):
    """No outline of the mirror's shape stands out in the photo.

    ``outline`` is the outline a refusal was about, ``(centre (row, col), radius)`` in
    px, where it was a well-fitted outline refused for its contrast alone (its edges no
    more prominent than their surroundings, :data:`MIN_EDGE_PROMINENCE`): a start for
    a fit that does not go by edges (a limb's, :func:`_limb_or_edge`); else None.

    Parameters
    ----------
    message : str
        What was not found, and why (one line, shown to the user).
    outline : ((float, float), float), optional
        The refused outline's centre (row, col) and radius, px (see above).
    """

    def __init__(self, message: str, *,
                 outline: tuple[tuple[float, float], float] | None = None) -> None:
        super().__init__(message)
        self.outline = outline


class SetupMismatchError(CalibrationError):
    """A mirror was found, but its size is far from the setup's prediction."""


@dataclass(frozen=True)
class RimFit:
    """Where the outline was found.

    ``center_px`` is the optical axis's pixel ``(row, col)`` (the image of the mirror's
    vertex; the circle's centre for an untilted mirror), ``scale`` the outline's size
    relative to the prediction; ``points_used`` of ``points_total`` outline points were
    inliers with normal residual RMS ``residual_rms_px``, which leaves the centre's row
    and column uncertain by ``center_se_px`` (standard error, the larger of the two).
    ``edge_points_px`` (N, 2) are the inliers' sub-pixel edge positions (row, col).
    ``roll_deg`` is the camera's roll about its axis (degrees, counter-clockwise in the
    image as displayed), fitted where the outline shows it (a tilted mirror's), else None.
    ``edge_width_px`` is the inliers' median edge width (RMS width of the derivative lobe)
    and ``residual_tolerance_px`` the residual RMS the fit was allowed (see
    :data:`RESIDUAL_WIDTH_SHARE`). ``limb`` is True where the outline was found as a
    limb without an edge (:func:`mitsweep.photo.limb.fit_limb`).

    Attributes
    ----------
    center_px : (float, float)
        The optical axis's pixel ``(row, col)``.
    scale : float
        The outline's size relative to the prediction.
    points_used, points_total : int
        Inliers, of the outline's points.
    residual_rms_px : float
        RMS of the inliers' normal residuals, px.
    edge_points_px : (N, 2) ndarray
        The inliers' sub-pixel edge positions ``(row, col)``, px.
    iterations : int
        Refinement passes made.
    center_se_px : float
        Standard error of the centre, px (the larger of row and column).
    roll_deg : float or None
        The camera's roll about its axis, degrees, where fitted.
    edge_width_px : float
        The inliers' median edge width, px.
    residual_tolerance_px : float
        The residual RMS the fit was allowed, px.
    limb : bool
        Whether the outline was found as a limb without an edge.
    prominence : float
        How much the fitted outline stands out from what lies beside it
        (:func:`mitsweep.photo.edges.edge_prominence`; NaN for a limb fit).
    """

    center_px: tuple[float, float]
    scale: float
    points_used: int
    points_total: int
    residual_rms_px: float
    edge_points_px: np.ndarray = field(repr=False)
    iterations: int = 0
    center_se_px: float = math.nan
    roll_deg: float | None = None
    edge_width_px: float = math.nan
    residual_tolerance_px: float = math.nan
    limb: bool = False
    prominence: float = math.nan


def _rotated(v: np.ndarray, angle: float) -> np.ndarray:
    """(N, 2) ``(drow, dcol)`` vectors turned by ``angle`` rad, counter-clockwise as
    displayed (rows down)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]], axis=-1)


def _roll_column(pts: np.ndarray, nrm: np.ndarray) -> np.ndarray:
    """(N,) normal displacement of each outline point per radian of roll about the
    axis: ``(J p) · n`` with ``J p`` the derivative of :func:`_rotated` at 0."""
    return -pts[:, 1] * nrm[:, 0] + pts[:, 0] * nrm[:, 1]


def _in_void(void: np.ndarray, centre, scale: float, pts: np.ndarray) -> np.ndarray:
    """(N,) bool: outline points (at ``centre``, ``scale``) on the photo's void; points
    outside the image are not (they are counted as missing, as before)."""
    if not void.any():
        return np.zeros(len(pts), bool)
    at = np.rint(np.asarray(centre)[None, :] + scale * pts).astype(int)
    H, W = void.shape
    inside = (at[:, 0] >= 0) & (at[:, 0] < H) & (at[:, 1] >= 0) & (at[:, 1] < W)
    out = np.zeros(len(pts), bool)
    out[inside] = void[at[inside, 0], at[inside, 1]]
    return out


def working_factor(shape: tuple[int, ...]) -> int:
    """The whole factor a photo of ``shape`` (H, W, ...) is reduced by for the search:
    its shorter side over :data:`WORKING_SIDE_PX`, rounded (1: searched as it is).

    Parameters
    ----------
    shape : tuple of int
        The photo's shape.
    """
    return max(1, int(round(min(shape[0], shape[1]) / WORKING_SIDE_PX)))


def working_luminance(image: np.ndarray, min_side: int) -> np.ndarray:
    """The luminance a rim search works on, after the memory gate for its work arrays
    (:data:`WORK_BYTES_PER_PIXEL`); :class:`NoMirrorError` for an image that is not
    (H, W[, C]) with both sides at least ``min_side``.

    Parameters
    ----------
    image : ndarray
        The photo, (H, W) or (H, W, C).
    min_side : int
        Smallest side accepted, px.
    """
    shape = np.shape(image)
    if len(shape) < 2:
        raise NoMirrorError(f"the photo must be an image, got shape {shape}")
    check_allocation(f"calibration of a {shape[1]}x{shape[0]} photo",
                     WORK_BYTES_PER_PIXEL * float(shape[0]) * shape[1])
    lum = luminance(image)
    if lum.ndim != 2 or min(lum.shape) < min_side:
        raise NoMirrorError(f"the photo must be an image of at least {min_side}x{min_side} "
                            f"pixels, got shape {shape}")
    return lum


@renamed_keywords(pitch="pixel_pitch")
def fit_rim(image: np.ndarray, outline: RimOutline, pixel_pitch: float, *,
            scale_range: tuple[float, float] = (1 - PLAUSIBLE_SCALE, 1 + PLAUSIBLE_SCALE),
            max_iterations: int = 30, edge_half_width_px: float | None = None,
            fit_roll: bool = False, starts: int = MAX_CANDIDATES) -> RimFit:
    """Find the predicted outline in a photograph (see the module docstring, and for a
    limb :func:`_limb_or_edge`); parameters, result and errors as :func:`fit_edges`.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        Linear photograph.
    outline : RimOutline
        The setup's prediction (:func:`predicted_outline`).
    pixel_pitch : float
        Pixel pitch of the photograph, mm.
    scale_range : (float, float)
        Outline sizes searched, relative to the prediction.
    max_iterations : int
        Refinement passes at most.
    edge_half_width_px : float, optional
        Half-width of the edge search along each normal (default: from the outline size).
    fit_roll : bool
        Also fit the camera's roll about its axis (a tilted mirror's outline shows it).
    starts : int
        The coarse search's starting points refined at most (see the module docstring);
        1 refines only the outline nearest the prediction from each normal's strongest
        edge: faster, for a setup known to be right within a few per cent.
    """
    factor = working_factor(np.shape(image)[:2])
    if factor >= 2:
        small = reduce_by(working_luminance(image, 8), factor)
        found = fit_rim(small, outline, pixel_pitch * factor, scale_range=scale_range,
                        max_iterations=max_iterations,
                        edge_half_width_px=None if edge_half_width_px is None
                        else edge_half_width_px / factor, fit_roll=fit_roll, starts=starts)
        logger.info("rim search at 1/%d: centre (%.1f, %.1f) px, scale %.4f", factor,
                    *(factor * c + (factor - 1) / 2 for c in found.center_px), found.scale)
        return refine_at_full_resolution(image, outline, pixel_pitch, found, factor,
                                         max_iterations=max_iterations)
    if outline.on_rim.any():
        return fit_edges(image, outline, pixel_pitch, scale_range=scale_range,
                         max_iterations=max_iterations,
                         edge_half_width_px=edge_half_width_px, fit_roll=fit_roll,
                         starts=starts)
    return _limb_or_edge(image, outline, pixel_pitch, scale_range=scale_range,
                         max_iterations=max_iterations,
                         edge_half_width_px=edge_half_width_px, fit_roll=fit_roll,
                         starts=starts)


def refine_at_full_resolution(image: np.ndarray, outline: RimOutline, pixel_pitch: float,
                              fit: RimFit, factor: int, *, max_iterations: int = 30) -> RimFit:
    """An outline found on a copy of ``image`` reduced by ``factor`` (block means, the
    outline at ``factor`` times the pitch), refined at full resolution within
    :data:`REFINE_WINDOW_REDUCED_PX` reduced pixels of it: the edges along its normals
    (:func:`fit_edges`' refinement and tests), or a limb (:func:`mitsweep.photo.limb.fit_limb`).
    Where the refinement is refused or strays beyond that window, the reduced fit itself,
    in full-resolution pixels (found and validated at the working size, it is as good
    as that size allows: a few hundredths of its pixels on the renders).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        The full-resolution photo.
    outline : RimOutline
        The outline searched for.
    pixel_pitch : float
        The photo's pixel pitch, mm.
    fit : RimFit
        The outline found on the reduced copy (its pixels).
    factor : int
        The reduction.
    max_iterations : int
        Refinement passes at most.
    """
    f = int(factor)
    centre = (fit.center_px[0] * f + (f - 1) / 2, fit.center_px[1] * f + (f - 1) / 2)
    reduced = replace(fit, center_px=centre,
                      edge_points_px=fit.edge_points_px * f + (f - 1) / 2,
                      residual_rms_px=fit.residual_rms_px * f,
                      center_se_px=fit.center_se_px * f, edge_width_px=fit.edge_width_px * f,
                      residual_tolerance_px=fit.residual_tolerance_px * f)
    lum = working_luminance(image, 8)
    pts, nrm = outline.offsets_px(pixel_pitch)
    radius = outline.equivalent_radius_px(pixel_pitch)
    window = REFINE_WINDOW_REDUCED_PX * f
    void = photo_void(image)
    hidden = _in_void(void, centre, fit.scale, pts)
    if void.any() and (~void).any() and (fit.limb or hidden.mean() <= 1.0 - MIN_INLIER_FRACTION):
        lum = fill_void(lum, void)
    else:   # nothing hidden, or a clipped black background (see fit_edges)
        void = np.zeros(lum.shape, bool)
    try:
        if fit.limb:
            from .limb import fit_limb

            step = 1.0 + window / (radius * fit.scale)
            limb = fit_limb(lum, centre, pts, nrm, (fit.scale / step, fit.scale * step),
                            shown=~void if void.any() else None, near_px=radius * fit.scale,
                            stride=f)
            if limb is None:
                raise NoMirrorError("no limb found at full resolution")
            refined = rim_fit_of_limb(limb, pts, nrm, radius)
        else:
            # the profiles smoothed f times as much (in full-resolution pixels) as at
            # the working size: the edge refined is the one found there, at its scale
            work = _Work(lum_s=smooth(lum, PROFILE_SMOOTHING_PX
                                      * (f if REFINE_SMOOTHING_GROWS else 1)),
                         sigma=noise_sigma(lum, ~void),
                         void=void, pts=pts, nrm=nrm, radius=radius, pitch=pixel_pitch,
                         half=window, max_iterations=max_iterations,
                         fit_roll=fit.roll_deg is not None)
            refined = _refine(work, centre, fit.scale, search_px=window)
    except NoMirrorError as exc:
        logger.info("refinement at full resolution refused (%s): the fit at 1/%d kept", exc, f)
        return reduced
    moved = max(math.dist(refined.center_px, centre), abs(refined.scale - fit.scale) * radius)
    if moved > window:
        logger.info("refinement at full resolution moved the outline by %.1f px (more than "
                    "%.1f): the fit at 1/%d kept", moved, window, f)
        return reduced
    return refined


def _limb_or_edge(image: np.ndarray, outline: RimOutline, pitch: float, *,
                  scale_range: tuple[float, float], max_iterations: int,
                  edge_half_width_px: float | None, fit_roll: bool,
                  starts: int = MAX_CANDIDATES) -> RimFit:
    """A limb outline (a hemisphere's, where the photo may show no edge): the limb's
    own fit (:func:`mitsweep.photo.limb.fit_limb`: the step of the fine-detail energy,
    then the sign-agnostic step of the mean) where it finds one, unless the edge fit
    (:func:`fit_edges`) finds an edge at it or outside it (a real ball's dark rim):
    an edge fit more than :data:`LIMB_INSIDE_SHARE` of the radius inside a limb found
    whose step has no consistent sign (:data:`MAX_LIMB_COHERENCE`) is an edge of the
    reflection (the rendered room's boards, 14% inside), not the outline. The limb fit
    starts from the edge fit's centre, or, where that was refused, the coarse search's,
    then the outline the edge fit refused for its contrast alone
    (:attr:`NoMirrorError.outline`: its centre, and its size for the limb's ridges)."""
    from .limb import fit_limb

    edge: RimFit | None = None
    refused: CalibrationError | None = None
    try:
        edge = fit_edges(image, outline, pitch, scale_range=scale_range,
                         max_iterations=max_iterations,
                         edge_half_width_px=edge_half_width_px, fit_roll=fit_roll,
                         starts=starts)
    except CalibrationError as exc:
        refused = exc
    lum = working_luminance(image, 8)
    pts, nrm = outline.offsets_px(pitch)
    void = photo_void(image)
    shown: np.ndarray | None = ~void
    if void.any() and shown is not None and shown.any():
        lum = fill_void(lum, void)
    else:
        shown = None
    faint = getattr(refused, "outline", None)
    radius = outline.equivalent_radius_px(pitch)

    def limb_starts() -> Iterator[tuple[tuple[float, float], float | None]]:
        # the edge fit's centre, then the coarse search's (an edge fitted to an outline
        # inside the limb, off its centre: the boards' edge in a 16-spp sweep render; the
        # search runs only where the first start finds no limb)
        if edge is not None:
            yield edge.center_px, None
        yield coarse_search(lum, pts, nrm, search_scales(*scale_range))[0], None
        if edge is None and faint is not None:
            # then an outline fitted all round but refused for its contrast alone (the
            # PAGEOS balloon's limb, whose top the draped Mylar hides: 9-10 px from the
            # coarse search's start, and 54% larger than a setup 35% off predicts)
            yield faint

    limb = None
    for start, near in limb_starts():
        limb = fit_limb(lum, start, pts, nrm, scale_range, shown=shown, near_px=near)
        if limb is not None and not scale_range[0] * 0.96 <= limb.radius_px / radius \
                <= scale_range[1] * 1.04:
            limb = None
        if limb is not None:
            break
    if limb is None or (edge is not None
                        and (edge.scale * radius >= (1.0 - LIMB_INSIDE_SHARE) * limb.radius_px
                             or limb.step_coherence > MAX_LIMB_COHERENCE)):
        if edge is None:
            assert refused is not None  # the edge fit either returned or raised
            raise refused
        return edge
    logger.info("limb fit: centre (%.2f, %.2f) px, radius %.2f px (energy step %.2f; the "
                "edge fit %s)", *limb.center_px, limb.radius_px, limb.energy_step,
                f"found {edge.scale * radius:.2f} px" if edge is not None else "refused")
    return rim_fit_of_limb(limb, pts, nrm, radius)


def rim_fit_of_limb(limb: LimbFit, pts: np.ndarray, nrm: np.ndarray,
                    radius_px: float) -> RimFit:
    """A limb found (:func:`mitsweep.photo.limb.fit_limb`) as a :class:`RimFit` of the
    outline it was fitted to (``limb`` True; no edge width, tolerance or roll), with the
    centre's standard error from its inliers' residuals.

    Parameters
    ----------
    limb : mitsweep.photo.limb.LimbFit
        The limb fit.
    pts, nrm : (N, 2) ndarray
        The outline's points (offsets from the axis, px) and outward normals it was
        fitted to.
    radius_px : float
        The outline's radius, px (:meth:`RimOutline.equivalent_radius_px`): the fit's
        ``scale`` is the limb's radius over it.
    """
    A = np.column_stack([nrm[:, 0], nrm[:, 1], np.sum(pts * nrm, axis=1)])
    used, res = limb.used_index, limb.residuals_px
    se = centre_standard_error(A[used], res, limb.points_used / limb.points_total
                               * 2.0 * math.pi * limb.radius_px)
    return RimFit(center_px=limb.center_px, scale=float(limb.radius_px / radius_px),
                  points_used=limb.points_used, points_total=limb.points_total,
                  residual_rms_px=limb.residual_rms_px, edge_points_px=limb.edge_points_px,
                  iterations=0, center_se_px=se, roll_deg=None, edge_width_px=math.nan,
                  residual_tolerance_px=math.nan, limb=True)


@renamed_keywords(pitch="pixel_pitch")
def fit_edges(image: np.ndarray, outline: RimOutline, pixel_pitch: float, *,
            scale_range: tuple[float, float] = (1 - PLAUSIBLE_SCALE, 1 + PLAUSIBLE_SCALE),
            max_iterations: int = 30, edge_half_width_px: float | None = None,
            fit_roll: bool = False, starts: int = MAX_CANDIDATES) -> RimFit:
    """Find the predicted outline in a photograph (see the module docstring).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        Linear photograph.
    outline : RimOutline
        The setup's prediction (:func:`predicted_outline`).
    pixel_pitch : float
        Pixel pitch of the photograph, mm.
    scale_range : (float, float)
        Outline sizes searched, relative to the prediction (default: the plausible
        ±:data:`PLAUSIBLE_SCALE`).
    max_iterations : int
        Refinement passes at most (each resamples the edges at the current fit).
    edge_half_width_px : float, optional
        Half-width of the edge search along each normal (default: from the outline size:
        1.5% of its radius, at least 4 px).
    fit_roll : bool
        Also fit the camera's roll about its axis, where the outline shows it (not a
        circle about the axis). A roll the fit leaves out moves a tilted outline's axis
        by ~0.5% of its radius per degree; fitted, it is nearly a shift of that outline,
        so the centre's standard error grows (x2.5 on the rendered tilted paraboloid,
        whose faint rim then reads as a 0.5-0.75 deg roll and the axis 0.26-0.31 px off,
        against 0.10-0.13 px without): fit it for a camera that may be turned on its
        mount.
    starts : int
        As :func:`fit_rim`.

    Returns
    -------
    RimFit

    Raises
    ------
    CalibrationError
        When too few outline points show a consistent edge or the residual is large:
        the photo does not show the mirror the setup describes.
    """
    if not (isinstance(starts, int) and starts >= 1):
        raise ValueError(f"starts must be a whole number of starting points, at least 1; "
                         f"got {starts!r}")
    lum = working_luminance(image, 8)
    pts, nrm = outline.offsets_px(pixel_pitch)
    radius = outline.equivalent_radius_px(pixel_pitch)
    if radius < 8:
        raise CalibrationError(f"the setup predicts a mirror image of radius {radius:.3g} px "
                               f"at pitch {pixel_pitch:g} mm: too small to calibrate on")
    scales = search_scales(*scale_range)
    void = photo_void(image)
    shown = ~void
    if void.any() and shown.any():
        filled = fill_void(lum, void)
        begin = coarse_candidates(filled, pts, nrm, scales, max_candidates=starts)
        hidden = _in_void(void, begin[0][0], begin[0][1], pts)
        if hidden.mean() > 1.0 - MIN_INLIER_FRACTION:
            # exact zeros around most of the rim: a clipped black background, not a
            # renderer's skipped pixels; the rim's edge against it is real
            logger.info("%.0f%% of the outline borders exact zeros: not treated as "
                        "outside the photo", 100 * hidden.mean())
            void[:] = False
            shown[:] = True
            begin = coarse_candidates(lum, pts, nrm, scales, max_candidates=starts)
        else:
            logger.info("%d px of exact zeros treated as outside the photo (%.0f%% of the "
                        "outline)", int(void.sum()), 100 * hidden.mean())
            lum = filled
    else:
        begin = coarse_candidates(lum, pts, nrm, scales, max_candidates=starts)
    work = _Work(lum_s=smooth(lum, PROFILE_SMOOTHING_PX), sigma=noise_sigma(lum, shown),
                 void=void, pts=pts, nrm=nrm, radius=radius, pitch=pixel_pitch,
                 half=edge_half_width_px, max_iterations=max_iterations,
                 fit_roll=bool(fit_roll) and float(np.sqrt(np.mean(
                     _roll_column(pts, nrm) ** 2))) > ROLL_OBSERVABLE * radius)
    fits: list[RimFit] = []
    refusals: list[NoMirrorError] = []
    for i, (centre, scale, coarse_score) in enumerate(begin):
        logger.info("coarse rim search, start %d: centre (%.1f, %.1f) px, scale %.3f "
                    "(score %.3g)", i, *centre, scale, coarse_score)
        for consensus in (False, True)[:1 if starts == 1 else 2]:
            try:
                fit = _refine(work, centre, scale, consensus=consensus,
                              passes=None if i == 0 and not consensus else START_PASSES)
            except NoMirrorError as exc:
                logger.info("start %d%s refused: %s", i, " (consensus)" if consensus
                            else "", exc)
                refusals.append(exc)
                continue
            fits.append(fit)
            if settled(fits[0]):
                break
        if fits and settled(fits[0]):
            logger.info("the first fit explains its edges so well that it is kept: %d of "
                        "%d starts refined", i + 1, len(begin))
            break
    if not fits:
        raise refusals[0]
    if CONCENTRIC_STARTS and starts > 1 and not settled(fits[0]):
        fits += _concentric_fits(work, fits[0], [scale for _, scale, _ in begin])
    return choose_fit(fits)


def _concentric_fits(work: _Work, first: RimFit, scales: list[float]) -> list[RimFit]:
    """Fits refined about the centre of ``first`` (a validated fit that did not
    :func:`settle <settled>`) at the coarse starts' scales, each at least a coarse scale
    step from those already refined, from the outline most normals show an edge on within
    two scale steps (:data:`CONCENTRIC_STARTS`): a mirror's rim inside its mount is
    concentric with it, and the coarse search's centres can be tens of pixels off (on
    omni_kaidan.jpg enlarged twice the first start, 7 px off, led to the mount's edge and
    the other five lay 48-118 px off: none reached the rim)."""
    fits: list[RimFit] = []
    tried = [first.scale]
    for scale in scales:
        if min(abs(scale / t - 1.0) for t in tried) < COARSE_SCALE_STEP - 1.0:
            continue
        tried.append(scale)
        try:
            fit = _refine(work, first.center_px, scale, consensus=True, passes=START_PASSES,
                          search_px=2.0 * (COARSE_SCALE_STEP - 1.0) * work.radius * scale)
        except NoMirrorError as exc:
            logger.info("concentric start at scale %.3f refused: %s", scale, exc)
            continue
        logger.info("concentric start at scale %.3f: a fit at scale %.4f", scale, fit.scale)
        fits.append(fit)
        tried.append(fit.scale)
    return fits


@dataclass(frozen=True)
class _Work:
    """What every refinement of one photo shares (:func:`_refine`)."""

    lum_s: np.ndarray
    sigma: float
    void: np.ndarray
    pts: np.ndarray
    nrm: np.ndarray
    radius: float
    pitch: float
    half: float | None
    max_iterations: int
    fit_roll: bool


def fit_support(fit: RimFit) -> float:
    """How well a fit is supported: the edge points it explains over their RMS residual
    (floored at :data:`SUPPORT_RMS_FLOOR_PX`): many edges, tightly on the outline. An
    outline through whatever edges lie within the search window (texture, a reflection's
    content) explains many points loosely; a rim explains them to a fraction of a
    pixel.

    Parameters
    ----------
    fit : RimFit
        A validated fit.
    """
    return fit.points_used / max(fit.residual_rms_px, SUPPORT_RMS_FLOOR_PX)


def unbeatable(fit: RimFit) -> bool:
    """Whether no fit could be :data:`CLEARLY_BETTER` supported than ``fit``
    (:func:`fit_support`: none explains more than all the points, or any to below
    :data:`SUPPORT_RMS_FLOOR_PX`): the other starting points need not be refined, and
    the result is the same.

    Parameters
    ----------
    fit : RimFit
        The first validated fit.
    """
    return CLEARLY_BETTER * fit_support(fit) >= fit.points_total / SUPPORT_RMS_FLOOR_PX


def settled(fit: RimFit) -> bool:
    """Whether ``fit``, the first validated, is kept without refining the other starting
    points: :func:`unbeatable`, or explaining :data:`SETTLED_SHARE` of the outline's
    points within :data:`SETTLED_RMS_PX` RMS. An outline of something else rarely fits
    that tightly all round (the distractors on the real photos of ``tests/data/real``
    fit at 2.4-3.7 px); the renders' rims fit at 0.1-0.4 px.

    Parameters
    ----------
    fit : RimFit
        The first validated fit.
    """
    return unbeatable(fit) or (fit.residual_rms_px <= SETTLED_RMS_PX
                               and fit.points_used >= SETTLED_SHARE * fit.points_total)


def choose_fit(fits: list[RimFit]) -> RimFit:
    """The fit kept of those refined from the coarse search's starting points (the first
    is :func:`coarse_search`'s, the outline nearest the prediction): the first, unless
    the best supported (:func:`fit_support`) has :data:`CLEARLY_BETTER` times its
    support.

    Parameters
    ----------
    fits : list of RimFit
        The validated fits, the first from the outline nearest the prediction.
    """
    for f in fits:
        logger.info("candidate fit: centre (%.2f, %.2f) px, scale %.4f, %d points, rms "
                    "%.3f px, prominence %.2f, support %.0f", *f.center_px, f.scale,
                    f.points_used, f.residual_rms_px, f.prominence, fit_support(f))
    best = max(fits, key=fit_support)
    return best if fit_support(best) > CLEARLY_BETTER * fit_support(fits[0]) else fits[0]


def _consensus_start(work: _Work, centre: tuple[float, float], scale: float,
                    search: float) -> tuple[tuple[float, float], float] | None:
    """The outline (centre, scale) near a starting point that the most normals show an
    edge on, any of their :data:`CONSENSUS_EDGES` strongest within ``search`` px
    (:func:`mitsweep.photo.robust.consensus_lstsq`, agreeing within
    :data:`CONSENSUS_TOLERANCE_PX` or a share of the radius); None where no outline
    gets :data:`MIN_INLIER_FRACTION` of the normals.

    Parameters
    ----------
    work : _Work
        The photo's shared arrays.
    centre : (float, float)
        Starting centre ``(row, col)``, px.
    scale : float
        Starting scale.
    search : float
        Half-width of the window along each normal, px.
    """
    pts, nrm = work.pts, work.nrm
    cand = edge_candidates(work.lum_s, centre, scale, pts, nrm, search, work.sigma,
                           k=CONSENSUS_EDGES)
    A = np.column_stack([nrm[:, 0], nrm[:, 1], np.sum(pts * nrm, axis=1)])
    tol = max(CONSENSUS_TOLERANCE_PX, 0.5 * RESIDUAL_RADIUS_SHARE * work.radius * scale)
    x, chosen = consensus_lstsq(A, cand, tol)
    agree = int(np.isfinite(chosen).sum())
    if not np.all(np.isfinite(x)) or agree < MIN_INLIER_FRACTION * len(pts):
        logger.info("consensus start: none (%d normals agree)", agree)
        return None
    logger.info("consensus start: %d of %d normals agree within %.2f px: moved by (%.2f, "
                "%.2f) px, scale %+.4f", agree, len(pts), tol, x[0], x[1], x[2])
    return (centre[0] + float(x[0]), centre[1] + float(x[1])), scale + float(x[2])


def _refine(work: _Work, centre: tuple[float, float], scale: float, *,
            consensus: bool = False, passes: int | None = None,
            search_px: float | None = None) -> RimFit:
    """Refine one starting point to sub-pixel edges and validate it (steps 2 and 3 of
    the module docstring); :class:`NoMirrorError` where the outline found fails a test.
    With ``consensus``, the first step is the outline most normals show an edge on
    (:func:`_consensus_start`) rather than the fit of each normal's strongest edge."""
    pts0, nrm0, radius, pixel_pitch = work.pts, work.nrm, work.radius, work.pitch
    void, lum_s, sigma, fit_roll = work.void, work.lum_s, work.sigma, work.fit_roll
    half = work.half or max(4.0, 0.015 * radius * scale)
    n = len(pts0)
    off = np.full(n, np.nan)
    used = np.zeros(n, bool)
    rms = math.inf
    it = 0
    # The camera's roll about its axis turns the outline about the axis point: a circle
    # about the axis does not show it, a tilted mirror's outline does.
    pts, nrm = pts0, nrm0
    roll = 0.0
    # The first window covers the coarse search's steps: a reduced pixel and a scale step.
    factor = max(1, int(radius / COARSE_RADIUS_PX))
    search = search_px or max(half, 1.5 * factor + (COARSE_SCALE_STEP - 1) * radius * scale)
    if consensus:
        moved = _consensus_start(work, centre, scale, search)
        if moved is None:
            raise NoMirrorError("no mirror found: no outline near this start that most "
                                "normals show an edge on")
        centre, scale = moved
        search = half
    limit = work.max_iterations if passes is None else min(passes, work.max_iterations)
    converged = False
    for it in range(1, limit + 1):  # noqa: B007 (passes made, reported)
        pts, nrm = _rotated(pts0, roll), _rotated(nrm0, roll)
        off, strength, width = edge_offsets(lum_s, centre, scale, pts, nrm, search,
                                         outermost=search <= half)
        # An edge must rise above the noise (a step of 3 σ of one pixel) to count; only
        # the outline's points the photo shows (not in its void) are asked for one.
        seen = ~_in_void(void, centre, scale, pts)
        n_seen = int(seen.sum())
        good = np.isfinite(off) & (strength > 3.0 * sigma + 1e-12) & seen
        if good.sum() < max(8, MIN_INLIER_FRACTION * n_seen):
            raise NoMirrorError(
                f"no mirror found: only {int(good.sum())} of {n} points of the predicted "
                f"outline (radius {radius:.1f} px at pitch {pixel_pitch:g} mm) show an edge; "
                f"check that the photo shows the mirror of this setup")
        # Normal displacement of point j: n_j · dc + dk (p_j · n_j) [+ dθ k (J p_j · n_j)].
        cols = [nrm[:, 0], nrm[:, 1], np.sum(pts * nrm, axis=1)]
        if fit_roll:
            cols.append(scale * _roll_column(pts, nrm))
        A = np.column_stack(cols)[good]
        b = off[good]
        # An edge's position is as uncertain as noise / contrast (down to a floor set by
        # the texture): residuals are standardised by that before the robust weights, so
        # that a few sharp edges off the rim (content touching it) are rejected rather
        # than hidden in the spread of the many faint ones.
        snr = np.minimum(strength[good] / (sigma + 1e-30), MAX_EDGE_SNR)
        x, wts = tukey_lstsq(A, b, 1.0 / snr)
        res = b - A @ x
        centre = (centre[0] + x[0], centre[1] + x[1])
        scale += x[2]
        d_roll = float(x[3]) if fit_roll else 0.0
        roll += d_roll
        inl = wts > 0
        used = np.zeros(n, bool)
        used[np.flatnonzero(good)[inl]] = True
        rms = float(np.sqrt(np.mean(res[inl] ** 2))) if inl.any() else math.inf
        search = max(half, min(search, 4.0 * np.abs(x[:2]).max() + 2.0))
        # Converged: the step is below 1e-3 px, or (a large, soft rim whose reweighting
        # keeps shifting it by more) below a twentieth of the centre's statistical
        # uncertainty, rms / sqrt(independent points / 2).
        indep = max(2.0, min(float(inl.sum()),
                             2.0 * math.pi * radius * scale / EDGE_CORRELATION_PX))
        resolution = max(1e-3, STEP_SHARE_OF_SE * rms * math.sqrt(2.0 / indep))
        if np.abs(x[:2]).max() < resolution and \
                max(abs(x[2]), abs(d_roll)) * radius < resolution:
            converged = True
            break
    if passes is not None and not converged:
        raise NoMirrorError(f"no mirror found: the outline did not settle in {limit} passes")
    pts, nrm = _rotated(pts0, roll), _rotated(nrm0, roll)
    n_used = int(used.sum())
    prominence = edge_prominence(lum_s, centre, scale, pts, nrm, half, radius * scale)
    logger.info("rim fit: %d of %d points, rms %.3f px, edge prominence %.2f after %d "
                "passes", n_used, n, rms, prominence, it)
    if prominence < MIN_EDGE_PROMINENCE:
        raise NoMirrorError(
            f"no mirror found: the best outline found (radius {radius * scale:.1f} px) is "
            f"no clearer an edge than its surroundings (prominence {prominence:.2f}, need "
            f"{MIN_EDGE_PROMINENCE:g}); check that the photo shows the mirror of this setup",
            outline=((float(centre[0]), float(centre[1])), float(radius * scale)))
    centre_se = centre_standard_error(A[inl], res[inl], n_used / n * radius * scale
                                       * 2.0 * math.pi) if inl.any() else math.inf
    logger.info("rim fit: centre standard error %.3f px", centre_se)
    n_edges = int(good.sum())
    edge_width = float(np.median(width[used])) if n_used else math.nan
    tolerance = max(MAX_RESIDUAL_RMS_PX, RESIDUAL_RADIUS_SHARE * radius * scale,
                    RESIDUAL_WIDTH_SHARE * edge_width if math.isfinite(edge_width) else 0.0)
    if n_used < MIN_CONSISTENT_FRACTION * n_edges or rms > tolerance:
        raise NoMirrorError(
            f"no mirror found: the best outline found fits {n_used} of the {n_edges} edge "
            f"points on its {n} with rms {rms:.2f} px (need {MIN_CONSISTENT_FRACTION:.0%} "
            f"within {tolerance:.3g} px, for edges {edge_width:.2f} px wide); check that "
            f"the photo shows the mirror of this setup")
    edges = np.asarray(centre)[None, :] + scale * pts + off[:, None] * nrm
    return RimFit(center_px=(float(centre[0]), float(centre[1])), scale=float(scale),
                  points_used=n_used, points_total=n, residual_rms_px=rms,
                  edge_points_px=edges[used], iterations=it, center_se_px=centre_se,
                  roll_deg=math.degrees(roll) if fit_roll else None,
                  edge_width_px=edge_width, residual_tolerance_px=tolerance,
                  prominence=prominence)
