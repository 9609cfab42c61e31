"""A sphere's limb, where the photo shows no edge in the mean: :func:`fit_limb`.

At the limb the reflection is grazing: a pixel ``δ`` inside it sees the background
~``K √δ`` px beyond it (``K`` ≈ 500 px for the bundled room at 200 px), so the mean
luminance continues across the limb, and what changes there is how the image varies:

* *inside*, each pixel averages the background over hundreds of its pixels: in a render
  its Monte Carlo noise is that of the whole background (large), in any image its mean is
  the background's far average;
* *outside*, each pixel sees one pixel's worth of background: little noise, the
  background's own value.

So (1) the local energy of the finest detail (the square of the diagonal second
difference, where a render's noise lives) steps down at the limb: a smooth step in the
log energy, fitted as a circle over an annulus (centre and radius shared by all the
pixels, not per normal), finds the limb to ~1 px; and (2) along each normal, the mean
steps at the limb by the local background's difference from its far average, a step of
random sign whose azimuthal mean cancels: a blurred step on a ramp fitted to each
normal's profile (:func:`mitsweep.photo.edges.blurred_step_offsets`), searched within a
pixel and a half of that circle, each normal weighted by its step's height and fitted
robustly (:func:`mitsweep.photo.robust.tukey_lstsq`), places it to a fraction of a
pixel. Measured in ``scripts/limb_study.py`` (32 spp, 200-1024 px, full frame, offset
and cropped; seeds 1-5 at 200 px): the centre within 0.07 px on the pinhole renders and
0.24 px on the sweep renders; with the peak of a smoothed profile's derivative for each
step and equal weights, within 0.18 px and 0.44 px (the sweep's beyond the 0.25 px bar
in 11 of 20 cases at 200 px).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace

import numpy as np

from .edges import blurred_step_offsets, edge_offsets
from .image import smooth
from .robust import tukey_lstsq

logger = logging.getLogger(__name__)

__all__ = [
    "LIMB_ANNULUS_PX",
    "LIMB_HALF_WIDTH_PX",
    "LIMB_SMOOTHING_PX",
    "LIMB_STEP_LOCATOR",
    "LIMB_STEP_LOCATORS",
    "LIMB_STEP_WEIGHT_RANGE",
    "MIN_RADIAL_RISE",
    "MIN_RADIAL_SHARE",
    "MIN_RIDGE",
    "PARTIAL_SHARE_RIDGE",
    "RADIAL_BAND_PX",
    "RADIAL_RISE_MIN_PIXELS",
    "RADIAL_SECTORS",
    "RIDGE_SMOOTHING_PX",
    "STRONG_ENERGY_STEP",
    "LimbFit",
    "energy_map",
    "fit_limb",
    "radial_rise",
    "radial_share",
]

#: Gaussian smoothing (px) of the luminance the sign of each normal's step is read on.
LIMB_SMOOTHING_PX = 1.0
#: Half-width (px) of the search for the step along each normal, about the circle the
#: energy step gives (that circle is within ~1 px of the limb).
LIMB_HALF_WIDTH_PX = 1.5
#: Largest ratio of two normals' weights in the limb's circle fit (each normal weighted by
#: the height of its step, :func:`_limb_from_ridge`). On the sweep renders of the sphere at
#: 200-1024 px (32 spp) weighting by height takes the centre from 0.35 px off at worst to
#: 0.24 px (``scripts/limb_study.py``).
LIMB_STEP_WEIGHT_RANGE = 10.0
#: How each normal's step is located in the limb's circle fit: ``"model"``, a blurred step
#: on a ramp fitted to the unsmoothed profile and weighted by its height
#: (:func:`mitsweep.photo.edges.blurred_step_offsets`, :data:`LIMB_STEP_WEIGHT_RANGE`),
#: or ``"peak"``, the peak of the smoothed profile's derivative
#: (:func:`mitsweep.photo.edges.edge_offsets`), every normal weighted alike (the fit
#: until stop 49, kept as the baseline). ``scripts/limb_study.py --locators model peak``
#: runs both side by side; docs/guide/restore.md gives the figures, which
#: tests/test_calibrate_limb.py measures.
LIMB_STEP_LOCATOR = "model"
#: The values :data:`LIMB_STEP_LOCATOR` may take.
LIMB_STEP_LOCATORS = ("model", "peak")
#: Half-width (px) of the annulus over which the energy step is fitted (at least; 6% of
#: the radius on large images).
LIMB_ANNULUS_PX = 6.0
#: Drop of the mean log fine-detail energy across the limb (inside minus outside,
#: natural log) from which it places the limb to start from: 2.3-5.6 on pinhole
#: renders (32 spp), 0.15-0.3 on sweep renders, where the ridge starts instead.
STRONG_ENERGY_STEP = 1.0
#: Gaussian smoothing (px) of the luminance whose radial derivative's ridge is fitted.
RIDGE_SMOOTHING_PX = 0.7
#: Smallest height of that ridge over the median squared radial derivative in the
#: annulus for a limb to be found.
MIN_RIDGE = 0.5
#: Share of the most prominent ridge's prominence from which a ridge is tried as the
#: limb, and how many are tried (nearest the predicted size first).
RIDGE_SHARE = 0.25
MAX_RIDGE_STARTS = 4
#: A reflection's detail runs along a sphere's limb: the mirror squeezes the scene behind
#: it into a thin annulus there, so just inside the limb the luminance changes faster
#: along the radius than across it, all round. A circle fitted to the texture of a photo
#: without a mirror has no such annulus. The limb is found only where, in at least
#: MIN_RADIAL_SHARE of RADIAL_SECTORS angular sectors, the squared radial derivative
#: carries more energy than the tangential one over ``[R - w, R - 2]`` px,
#: ``w = max(RADIAL_BAND_PX, 8 % of R)``. Measured (limb fits captured during
#: calibration): 0.83-1.00 on the sphere renders (200-400 px, full frame, off-centre,
#: cropped, the mirror's window alone) and the real chrome balls, PAGEOS and the dome;
#: 0.42-0.58 on the Kodak photo without a mirror. A cue, not a proof: on scikit-image's
#: sample photos (10 photos, 3 sizes: 30 cases) a limb is found in 4 cases (17 without
#: the cue, 10 without :data:`PARTIAL_SHARE_RIDGE`): round things with detail along the
#: radius (a coffee cup's rim) and circles along strong edges (a brick wall's mortar)
#: pass (tests/test_calibrate_limb.py holds both kinds).
RADIAL_SECTORS = 12
RADIAL_BAND_PX = 8.0
MIN_RADIAL_SHARE = 0.8
#: Where the detail runs along the limb in most sectors but not all (a plain stretch of
#: background behind a ball, whose noise points anywhere; or a circle fitted to a fine
#: texture, whose direction is random), the limb must also stand out: its ridge (see
#: :data:`MIN_RIDGE`) at least this many times the annulus' median. Measured (limb fits
#: found during calibration): the true limbs with a disagreeing sector, sphere_tokyo.jpg
#: (25-47) and a 16-spp sweep render at 200 px (3.4); the circles in scikit-image's
#: samples that pass MIN_RADIAL_SHARE with a disagreeing sector, the cat, grass and
#: gravel photos (0.56-1.70), now refused. Every sphere render found (pinhole and sweep,
#: 200-1024 px, 8-32 spp) reads 12 of 12 sectors, or 11 with this ridge.
PARTIAL_SHARE_RIDGE = 2.5
#: The squeeze grows toward the limb: a ray meeting the sphere at ``r = R sin θ`` in the
#: image is turned by ``2θ``, so the reflection is stretched ``1 / cos θ`` along the
#: radius and ``cos θ`` across it, and the detail along the radius outweighs the detail
#: across it by ~``1 / cos² θ`` (for a scene without a preferred direction): ~2 at
#: ``0.6 R``, ~10 from ``0.95 R``. :func:`radial_rise` measures how much more it does
#: just inside the limb (``[0.85 R, R - 2]``) than in the mirror's middle
#: (``[0.5 R, 0.7 R]``), as the difference of the log ratios; a limb needs at least
#: MIN_RADIAL_RISE. A circle that passes the direction cue because the photo's detail runs
#: along its radius everywhere (or nowhere) has no such rise. Measured (limb fits captured
#: during calibration): the sphere renders 1.07-2.15 (pinhole and sweep, 200-1024 px,
#: 8-32 spp, full frame, off-centre, cropped, the mirror's window alone), the real balls
#: 0.90 (sphere_tokyo.jpg), 1.40 (PAGEOS), 2.31 (sphere_lamp.jpg), the dome 3.76; the
#: circles scikit-image's sample photos passed the direction cue with: a brick wall's
#: mortar -0.14, a photo of text -0.51, the cat's eye in ``chelsea`` -0.41 (now
#: refused), and a coffee cup's rim 1.28 and the astronaut's portrait 1.33 (still
#: taken: round things whose detail runs along the radius toward their edge).
MIN_RADIAL_RISE = 0.4
#: Fewest shown pixels in either band for :func:`radial_rise` to be judged (a frame that
#: crops the mirror's middle away leaves the cue undecided).
RADIAL_RISE_MIN_PIXELS = 50


@dataclass(frozen=True)
class LimbFit:
    """A limb found: centre ``(row, col)`` and radius (px); ``energy_step`` the drop of
    the log fine-detail energy across it; ``energy_centre_px``/``energy_radius_px`` the
    energy step's circle (stage 1); ``points_used`` of ``points_total`` normals were the
    sign-agnostic step's inliers (``used_index`` into the outline's points, their normal
    residuals ``residuals_px``), with RMS residual ``residual_rms_px``.

    Attributes
    ----------
    center_px : (float, float)
        The limb's centre ``(row, col)``, px.
    radius_px : float
        Its radius, px.
    energy_step : float
        Drop of the log fine-detail energy across the limb (0 where stage 1 found none).
    ridge_height : float
        Height of the radial derivative's ridge over its median level.
    step_coherence : float
        Share of the normals whose bright/dark step across the limb has the fitted sign.
    radial_share : float
        Share of the :data:`RADIAL_SECTORS` sectors in which the detail just inside the
        limb runs along it (at least :data:`MIN_RADIAL_SHARE`).
    radial_rise : float
        How much more it does there than in the mirror's middle (:func:`radial_rise`,
        at least :data:`MIN_RADIAL_RISE`; NaN where the photo shows too little of either).
    energy_center_px : (float, float)
        Centre of the energy step's circle (stage 1), px.
    energy_radius_px : float
        Its radius, px.
    points_used, points_total : int
        Inliers of the sign-agnostic step fit, of the outline's normals.
    residual_rms_px : float
        RMS of the inliers' normal residuals, px.
    edge_points_px : (M, 2) ndarray
        The inliers' limb positions ``(row, col)``, px.
    used_index : (M,) int ndarray
        Their indices into the outline's points.
    residuals_px : (M,) ndarray
        Their normal residuals, px.
    """

    center_px: tuple[float, float]
    radius_px: float
    energy_step: float
    ridge_height: float
    step_coherence: float
    radial_share: float
    radial_rise: float
    energy_center_px: tuple[float, float]
    energy_radius_px: float
    points_used: int
    points_total: int
    residual_rms_px: float
    edge_points_px: np.ndarray
    used_index: np.ndarray
    residuals_px: np.ndarray


def energy_map(lum: np.ndarray) -> tuple[np.ndarray, float]:
    """Log energy of the finest detail, ``log(d² + ε)`` with ``d`` the diagonal second
    difference of each 2x2 block (its centre at ``(i + 0.5, j + 0.5)``), and ``ε`` a
    tenth of the median ``d²`` (so that flat patches do not dominate).

    Parameters
    ----------
    lum : (H, W) ndarray
        Luminance.
    """
    d = lum[1:, 1:] - lum[:-1, 1:] - lum[1:, :-1] + lum[:-1, :-1]
    d2 = d * d
    eps = 0.1 * float(np.median(d2)) + 1e-30
    return np.log(d2 + eps), eps


def _span(at: float, reach: float, n: int) -> tuple[int, int]:
    """The index range ``[lo, hi)`` of an axis of ``n`` pixels within ``reach`` (+2 px) of
    ``at``: empty, never reversed, where a fit has moved ``at`` off the image (a limb fit
    on a photo without a mirror: scikit-image's moon)."""
    lo = min(max(int(at - reach - 2), 0), n)
    return lo, max(min(int(at + reach + 3), n), lo)


def _window(centre, reach, shape, stride=1):
    """The pixel rows and columns within ``reach`` (+2 px) of ``centre``, every
    ``stride``-th of each, and the slices that cut them from an image of ``shape``."""
    r0, c0 = _span(centre[0], reach, shape[0]), _span(centre[1], reach, shape[1])
    sl = (slice(r0[0], r0[1], stride), slice(c0[0], c0[1], stride))
    rows, cols = np.mgrid[sl]
    return rows, cols, sl


def _radial_profile(e, centre, r_lo, r_hi, step=0.5, shown=None, stride=1):
    rows, cols, sl = _window(centre, r_hi, e.shape, stride)
    r = np.hypot(rows + 0.5 - centre[0], cols + 0.5 - centre[1])
    sub = e[sl]
    ok = (r >= r_lo) & (r < r_hi)
    if shown is not None:
        ok &= shown[sl]
    bins = np.arange(r_lo, r_hi + step, step)
    idx = np.digitize(r[ok], bins) - 1
    n = np.bincount(idx, minlength=len(bins))[:len(bins) - 1]
    s = np.bincount(idx, weights=sub[ok], minlength=len(bins))[:len(bins) - 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        return 0.5 * (bins[:-1] + bins[1:]), s / n


def _radial_start(e, centre, r_lo, r_hi, window, shown=None, stride=1):
    """The radius in ``[r_lo, r_hi]`` where the azimuthal mean log energy drops most
    from the ``window`` px inside to the ``window`` px outside, and that drop."""
    r, prof = _radial_profile(e, centre, max(r_lo - window, 1.0), r_hi + window, 0.5, shown,
                              stride)
    k = round(window / 0.5)
    best, at = -math.inf, math.nan
    for i in range(k, len(r) - k):
        if not r_lo <= r[i] <= r_hi:
            continue
        inside, outside = prof[i - k:i], prof[i:i + k]
        if np.isnan(inside).any() or np.isnan(outside).any():
            continue
        drop = float(inside.mean() - outside.mean())
        if drop > best:
            best, at = drop, float(r[i] - 0.25)
    return at, best


def _one_blas_thread():
    """A context in which BLAS runs on one thread: the fits below solve tall, narrow
    least-squares problems (tens of thousands of pixels, 6-7 parameters) whose SVD a
    second BLAS thread slows down (sphere_lamp.jpg, 1024²: 8.7 s wall and 12.9 s CPU on
    two threads, 6.1 s and 5.7 s on one)."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")


def _energy_step_fit(e, centre, radius, band, shown=None, stride=1):
    """Circle of the smooth step of the log energy over the annulus ``radius ± band``:
    ``a + b Φ((r - R)/w)`` by least squares (soft L1), returning centre, radius and the
    inside-minus-outside drop ``-b``."""
    from scipy.optimize import least_squares
    from scipy.special import erf

    rows, cols, sl = _window(centre, radius + band, e.shape, stride)
    y, x = rows + 0.5, cols + 0.5
    r = np.hypot(y - centre[0], x - centre[1])
    m = np.abs(r - radius) < band
    if shown is not None:
        m &= shown[sl]
    y, x, s, rm = y[m], x[m], e[sl][m], r[m]
    if len(s) < 50 or (rm < radius).all() or (rm >= radius).all():
        return centre, radius, 0.0   # too little of the annulus, or one side only, shown
    a0 = float(np.median(s[rm < radius]))
    b0 = float(np.median(s[rm >= radius])) - a0

    def resid(p):
        cy, cx, R, a, b, w = p
        rr = np.hypot(y - cy, x - cx)
        return a + b * 0.5 * (1.0 + erf((rr - R) / (math.sqrt(2.0) * abs(w) + 1e-3))) - s

    def jac(p):
        # analytic: the finite-difference Jacobian took 7 residual evaluations a step
        cy, cx, R, a, b, w = p
        dy, dx = y - cy, x - cx
        rr = np.maximum(np.hypot(dy, dx), 1e-12)
        den = math.sqrt(2.0) * abs(w) + 1e-3
        u = (rr - R) / den
        g = b * np.exp(-u * u) / (math.sqrt(math.pi) * den)   # d model / d rr
        return np.column_stack([g * -dy / rr, g * -dx / rr, -g, np.ones_like(rr),
                                0.5 * (1.0 + erf(u)),
                                -g * u * math.sqrt(2.0) * np.sign(w)])

    with _one_blas_thread():
        sol = least_squares(resid, [centre[0], centre[1], radius, a0, b0, 1.0], jac=jac,
                            loss="soft_l1", f_scale=float(np.std(s)) + 1e-12, max_nfev=200)
    cy, cx, R, _a, b, _w = sol.x
    return (float(cy), float(cx)), float(R), float(-b)


def _band_derivatives(gy, gx, centre, r_in, r_out, shown=None, stride=1):
    """The squared derivatives along and across the radius, and the angle, at the shown
    pixels ``r_in < r < r_out`` from ``centre`` (every ``stride``-th row and column)."""
    rows, cols, sl = _window(centre, r_out, gy.shape, stride)
    dy, dx = rows - centre[0], cols - centre[1]
    rr = np.maximum(np.hypot(dy, dx), 1e-9)
    m = (rr > r_in) & (rr < r_out)
    if shown is not None:
        m &= shown[sl]
    gyw, gxw = gy[sl][m], gx[sl][m]
    dy, dx, rr = dy[m], dx[m], rr[m]
    radial = ((gyw * dy + gxw * dx) / rr) ** 2
    across = ((gxw * dy - gyw * dx) / rr) ** 2
    return radial, across, np.arctan2(dy, dx)


def radial_share(gy: np.ndarray, gx: np.ndarray, centre: tuple[float, float],
                 radius: float, shown: np.ndarray | None = None, *, stride: int = 1) -> float:
    """Share of the :data:`RADIAL_SECTORS` angular sectors in which the gradient
    (``gy``, ``gx``) just inside the circle (see :data:`MIN_RADIAL_SHARE`) has more
    energy along the radius than across it; a sector with under 10 shown pixels there
    (a frame's crop) is not counted, and none counted reads 0.

    Parameters
    ----------
    gy, gx : (H, W) ndarray
        The luminance's derivatives along rows and columns.
    centre : (float, float)
        The circle's centre ``(row, col)``, px.
    radius : float
        Its radius, px.
    shown : (H, W) bool ndarray, optional
        Pixels the photo shows.
    stride : int
        Every ``stride``-th pixel row and column counted (a large photo's refinement:
        its reduced copy's spacing; the bands' pixel counts fall by ``stride²``).
    """
    width = max(RADIAL_BAND_PX, 0.08 * radius)
    radial, across, angle = _band_derivatives(gy, gx, centre, radius - width, radius - 2.0,
                                              shown, stride)
    sector = ((angle + math.pi) / (2.0 * math.pi) * RADIAL_SECTORS).astype(int) \
        % RADIAL_SECTORS
    counted = np.bincount(sector, minlength=RADIAL_SECTORS) >= 10
    along = np.bincount(sector, radial, RADIAL_SECTORS) > np.bincount(sector, across,
                                                                      RADIAL_SECTORS)
    return float(along[counted].mean()) if counted.any() else 0.0


def radial_rise(gy: np.ndarray, gx: np.ndarray, centre: tuple[float, float],
                radius: float, shown: np.ndarray | None = None, *, stride: int = 1) -> float:
    """How much more the gradient (``gy``, ``gx``) runs along the radius just inside the
    circle than in its middle (see :data:`MIN_RADIAL_RISE`): the natural log of the
    ratio of the squared derivative along the radius to the one across it, summed over
    ``[0.85 R, R - 2]`` px, minus the same over ``[0.5 R, 0.7 R]``. NaN where either band
    has under :data:`RADIAL_RISE_MIN_PIXELS` shown pixels or no detail.

    Parameters
    ----------
    gy, gx : (H, W) ndarray
        The luminance's derivatives along rows and columns.
    centre : (float, float)
        The circle's centre ``(row, col)``, px.
    radius : float
        Its radius, px.
    shown : (H, W) bool ndarray, optional
        Pixels the photo shows.
    stride : int
        Every ``stride``-th pixel row and column counted (a large photo's refinement:
        its reduced copy's spacing; the bands' pixel counts fall by ``stride²``).
    """
    logs = []
    for r_in, r_out in ((0.85 * radius, radius - 2.0), (0.5 * radius, 0.7 * radius)):
        radial, across, _ = _band_derivatives(gy, gx, centre, r_in, r_out, shown, stride)
        a, b = float(radial.sum()), float(across.sum())
        if radial.size < RADIAL_RISE_MIN_PIXELS or not (a > 0.0 and b > 0.0):
            return math.nan
        logs.append(math.log(a / b))
    return logs[0] - logs[1]


def _radial_gradient_sq(lum_s, gy, gx, centre, radius, band, stride=1):
    """Squared radial derivative (about ``centre``) of the smoothed luminance over the
    annulus ``radius ± band`` (every ``stride``-th row and column): pixel rows, cols and
    values, the annulus' mask in the window and the window's slices."""
    rows, cols, sl = _window(centre, radius + band, lum_s.shape, stride)
    dy, dx = rows - centre[0], cols - centre[1]
    rr = np.hypot(dy, dx)
    g = (gy[sl] * dy + gx[sl] * dx) / np.maximum(rr, 1e-9)
    m = np.abs(rr - radius) < band
    return rows[m].astype(np.float64), cols[m].astype(np.float64), g[m] ** 2, m, sl


def _ridge_fit(gy, gx, lum_s, centre, radius, band, shown=None, iterations=3, stride=1):
    """Circle of the ridge of the squared radial derivative: ``a + b exp(-q²/2w²) +
    c Φ(q/w)`` with ``q`` the distance from the circle (a ridge where the mean steps
    at the limb, whatever its sign, and a step where the texture changes), fitted by
    least squares (soft L1) over the annulus ``radius ± band``, the radial direction
    taken about the previous pass's centre. Returns centre, radius, the ridge height
    ``b`` over the median level, and the parameters."""
    from scipy.optimize import least_squares
    from scipy.special import erf

    p = None
    for _ in range(iterations):
        y, x, s, m, sl = _radial_gradient_sq(lum_s, gy, gx, centre, radius, band, stride)
        if shown is not None:
            keep = shown[sl][m]
            y, x, s = y[keep], x[keep], s[keep]
        if len(s) < 50:
            return centre, radius, 0.0, None
        med = float(np.median(s))

        def resid(q, y=y, x=x, s=s):
            cy, cx, R, a, b, c, w = q
            d = np.hypot(y - cy, x - cx) - R
            w = abs(w) + 0.05
            return a + b * np.exp(-d * d / (2.0 * w * w)) \
                + c * 0.5 * (1.0 + erf(d / (math.sqrt(2.0) * w))) - s

        def jac(q, y=y, x=x):
            # analytic: the finite-difference Jacobian took 8 residual evaluations a step
            cy, cx, R, a, b, c, w = q
            dy, dx = y - cy, x - cx
            rr = np.maximum(np.hypot(dy, dx), 1e-12)
            d = rr - R
            ww = abs(w) + 0.05
            e = np.exp(-d * d / (2.0 * ww * ww))
            gauss = e / (math.sqrt(2.0 * math.pi) * ww)             # d Phi(d/ww) / dd
            g = -b * e * d / (ww * ww) + c * gauss                  # d model / dd
            dw = (b * e * d * d / ww ** 3 - c * gauss * d / ww) * np.sign(w)
            return np.column_stack([g * -dy / rr, g * -dx / rr, -g, np.ones_like(rr), e,
                                    0.5 * (1.0 + erf(d / (math.sqrt(2.0) * ww))), dw])

        p0 = [centre[0], centre[1], radius, med, float(np.percentile(s, 90)) - med, 0.0, 1.0]
        with _one_blas_thread():
            sol = least_squares(resid, p0, jac=jac, loss="soft_l1",
                                f_scale=float(np.std(s)) + 1e-30, max_nfev=300)
        p = sol.x
        if abs(p[2] - radius) > band:  # ran off the annulus
            return centre, radius, 0.0, None
        centre, radius = (float(p[0]), float(p[1])), float(p[2])
    return centre, radius, float(p[4] / (med + 1e-30)), p


def _ridge_starts(gy, gx, lum_s, centre, r_lo, r_hi, predicted, shown=None, stride=1):
    """Radii of the ridges of the azimuthal mean squared radial derivative in
    ``[r_lo, r_hi]``: the peaks at least :data:`RIDGE_SHARE` as prominent as the most
    prominent (over the median within 6% of the radius), nearest ``predicted`` first."""
    mid = 0.5 * (r_lo + r_hi)
    step = 0.5
    k = max(2, round(0.06 * mid / step))
    # the profile reaches a median window beyond both ends, so that a ridge at the
    # range's end is judged as one inside it
    band = 0.5 * (r_hi - r_lo) + k * step + 4.0
    y, x, s, m, sl = _radial_gradient_sq(lum_s, gy, gx, centre, mid, band, stride)
    if shown is not None:
        keep = shown[sl][m]
        y, x, s = y[keep], x[keep], s[keep]
    r = np.hypot(y - centre[0], x - centre[1])
    bins = np.arange(mid - band, mid + band + step, step)
    idx = np.clip(np.digitize(r, bins) - 1, 0, len(bins) - 2)
    n = np.bincount(idx, minlength=len(bins) - 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        prof = np.log(np.bincount(idx, weights=s, minlength=len(bins) - 1) / n)
    rc = 0.5 * (bins[:-1] + bins[1:])
    cand = []
    for i in range(k, len(prof) - k):
        if not r_lo <= rc[i] <= r_hi or not np.isfinite(prof[i]):
            continue
        win = prof[i - k:i + k + 1]
        if prof[i] < np.nanmax(prof[i - 2:i + 3]):
            continue
        cand.append((float(prof[i] - np.nanmedian(win)), float(rc[i])))
    if not cand:
        return []
    top = max(c[0] for c in cand)
    strong = [c[1] for c in cand if c[0] >= RIDGE_SHARE * top]
    return sorted(strong, key=lambda r: abs(r - predicted))


def _steps(lum_s, centre, scale, pts, nrm) -> np.ndarray:
    """(N,) step of the mean across the circle at each outline point: outside (0.5-1.5
    px beyond it) minus inside (as far within)."""
    from scipy.ndimage import map_coordinates

    t = np.array([-1.5, -1.0, -0.5, 0.5, 1.0, 1.5])
    xy = np.asarray(centre)[None, None, :] + scale * pts[:, None, :] \
        + t[None, :, None] * nrm[:, None, :]
    prof = map_coordinates(lum_s, [xy[..., 0].ravel(), xy[..., 1].ravel()], order=1,
                           mode="nearest").reshape(xy.shape[:2])
    return prof[:, 3:].mean(axis=1) - prof[:, :3].mean(axis=1)


def _step_coherence(lum_s, centre, scale, pts, nrm, good) -> float:
    """``|mean Δ| / RMS Δ`` of the steps ``Δ`` of the mean across the circle (outside,
    0.5-1.5 px beyond it, minus inside, as far within) at the outline points ``good``:
    near 0 at a limb (the step's sign is the local background's against its far
    average), near 1 at an edge (a holder, a dark ring, a rim)."""
    d = _steps(lum_s, centre, scale, pts, nrm)[good]
    return float(abs(d.mean()) / (math.sqrt(float(np.mean(d * d))) + 1e-30))


def fit_limb(lum: np.ndarray, centre: tuple[float, float], pts: np.ndarray,
             nrm: np.ndarray, scale_range: tuple[float, float], *,
             shown: np.ndarray | None = None, iterations: int = 6,
             near_px: float | None = None, stride: int = 1) -> LimbFit | None:
    """Find a circular limb (see the module docstring) about ``centre`` (row, col; good
    to a few px), its size within ``scale_range`` times the outline ``pts`` (N, 2
    offsets from the axis, px, with outward normals ``nrm``). None where neither cue
    finds one (no energy drop of :data:`STRONG_ENERGY_STEP` and no ridge of the radial
    derivative :data:`MIN_RIDGE` times its median level).

    Parameters
    ----------
    lum : (H, W) ndarray
        Luminance.
    centre : (float, float)
        Starting centre ``(row, col)``, px.
    pts, nrm : (N, 2) ndarray
        The predicted outline's points (offsets from the axis, px) and outward normals.
    scale_range : (float, float)
        Limb sizes searched, relative to the outline.
    shown : (H, W) bool ndarray, optional
        Pixels the photo shows (a render's skipped pixels are not).
    iterations : int
        Refinement passes of the step fit at most.
    near_px : float, optional
        Where the fine-detail energy shows no step, the ridges nearest this radius (px)
        are tried first (default the outline's own size; an outline found otherwise,
        such as an edge fit refused for its contrast, is a better guess where the
        setup is far off).
    stride : int
        The circles of the annulus (the energy step, the ridge) and the direction cues
        are fitted to every ``stride``-th pixel row and column: a large photo's limb,
        refined at full resolution near the one found on a copy reduced ``stride``
        times, on as many pixels as there (the fit along the normals uses them all).
    """
    if int(stride) < 1:
        raise ValueError(f"stride must be a whole number of pixels >= 1, got {stride}")
    stride = int(stride)
    radius0 = float(np.sqrt(np.mean(np.sum(pts ** 2, axis=1))))
    r_lo, r_hi = radius0 * scale_range[0], radius0 * scale_range[1]
    e, _ = energy_map(lum)
    e_shown = None if shown is None else (shown[1:, 1:] & shown[:-1, 1:] & shown[1:, :-1]
                                          & shown[:-1, :-1])
    band = max(LIMB_ANNULUS_PX, 0.04 * radius0 * scale_range[0])
    lum_r = smooth(lum, RIDGE_SMOOTHING_PX)
    gy, gx = np.gradient(lum_r)
    start, drop = _radial_start(e, centre, r_lo, r_hi, band, e_shown, stride)
    step = 0.0
    c, R = centre, start
    if math.isfinite(start) and drop >= STRONG_ENERGY_STEP:
        for _ in range(2):
            c, R, step = _energy_step_fit(e, c, R, band, e_shown, stride)
    # the energy step's circle where there is one, then the ridges, nearest the
    # prediction first: after the energy step's circle fails (an edge inside the limb,
    # such as the reflected boards in a clean sweep render), and after a ridge whose
    # step fit does not settle in the range; not after a ridge the direction cues refuse
    # (the ridge nearest the prediction is a texture's circle: trying farther ones finds
    # circles in photos without a mirror, such as scikit-image's text sample)
    starts = [(c, R, step)] if step >= STRONG_ENERGY_STEP else []
    near = radius0 if near_px is None else float(near_px)
    starts += [(centre, r, 0.0) for r in _ridge_starts(gy, gx, lum_r, centre, r_lo, r_hi,
                                                         near, shown, stride)[:MAX_RIDGE_STARTS]]
    lum_s = smooth(lum, LIMB_SMOOTHING_PX)
    for c0, R0, step in starts:
        c, R, height, _ = _ridge_fit(gy, gx, lum_r, c0, R0, band, shown, stride=stride)
        if not (height >= MIN_RIDGE and r_lo / 1.04 <= R <= r_hi * 1.04):
            continue
        fit, by_cue = _limb_from_ridge(lum, lum_s, gy, gx, c, R / radius0, height, pts, nrm,
                                       (r_lo, r_hi), shown, iterations, stride)
        if fit is not None:
            return replace(fit, energy_step=float(step),
                           energy_center_px=(float(c0[0]), float(c0[1])),
                           energy_radius_px=float(R0))
        if by_cue and step < STRONG_ENERGY_STEP:
            return None
    logger.debug("limb fit from (%.1f, %.1f): no limb in %.1f-%.1f px (%d starts)",
                 *centre, r_lo, r_hi, len(starts))
    return None


def _limb_from_ridge(lum, lum_s, gy, gx, c, scale, height, pts, nrm, radii, shown, iterations,
                     stride=1):
    """The limb from a ridge's circle (centre ``c``, ``scale`` times the outline, ridge
    ``height``): the step of the luminance ``lum`` along each normal, whatever its sign,
    within LIMB_HALF_WIDTH_PX of that circle (a blurred step on a ramp,
    :func:`mitsweep.photo.edges.blurred_step_offsets`), each weighted by its height,
    fitted as the circle plus an offset of the bright-outside steps against the
    dark-outside ones, which the centre would otherwise absorb where one sign prevails on
    one side; then the direction cues (on ``lum_s``, smoothed). The fit (its energy
    step's fields the caller's), or None where it leaves ``radii`` (r_lo, r_hi) or a cue
    refuses it; and whether a cue did."""
    radius0 = float(np.sqrt(np.mean(np.sum(pts ** 2, axis=1))))
    r_lo, r_hi = radii
    A3 = np.column_stack([nrm[:, 0], nrm[:, 1], np.sum(pts * nrm, axis=1)])
    good = np.zeros(len(pts), bool)
    wts = res = np.zeros(0)
    off = np.full(len(pts), np.nan)
    if LIMB_STEP_LOCATOR not in LIMB_STEP_LOCATORS:
        raise ValueError(f"limb.LIMB_STEP_LOCATOR must be one of {LIMB_STEP_LOCATORS}, "
                         f"got {LIMB_STEP_LOCATOR!r}")
    for _ in range(iterations):
        if LIMB_STEP_LOCATOR == "model":
            off, heights, _sigma = blurred_step_offsets(lum, c, scale, pts, nrm,
                                                        LIMB_HALF_WIDTH_PX)
        else:
            off, heights, _width = edge_offsets(lum_s, c, scale, pts, nrm, LIMB_HALF_WIDTH_PX)
        good = np.isfinite(off)
        if shown is not None:
            at = np.rint(np.asarray(c)[None, :] + scale * pts).astype(int)
            H, W = shown.shape
            ins = (at[:, 0] >= 0) & (at[:, 0] < H) & (at[:, 1] >= 0) & (at[:, 1] < W)
            good &= ins
            good[ins] &= shown[at[ins, 0], at[ins, 1]]
        if good.sum() < 8:
            logger.debug("limb fit: %d normals show a step", int(good.sum()))
            return None, False
        sign = np.sign(_steps(lum_s, c, scale, pts, nrm))
        A = np.column_stack([A3, sign])[good]
        # a step's position is as uncertain as its height is small (the noise over the
        # step); the tallest tenth set the scale, and no normal counts less than a tenth
        h = np.abs(heights[good])
        top = max(float(np.quantile(h, 0.9)), 1e-300)
        uncertainty = np.clip(top / np.maximum(h, 1e-300), 1.0, LIMB_STEP_WEIGHT_RANGE) \
            if LIMB_STEP_LOCATOR == "model" else np.ones(len(h))
        x, wts = tukey_lstsq(A, off[good], uncertainty)
        res = off[good] - A @ x
        c = (c[0] + float(x[0]), c[1] + float(x[1]))
        scale += float(x[2])
        if max(abs(x[0]), abs(x[1]), abs(x[2]) * radius0) < 1e-3:
            break
    R = scale * radius0
    if not r_lo / 1.04 <= R <= r_hi * 1.04:
        logger.debug("limb fit: the step fit's radius %.1f px left %.1f-%.1f", R, r_lo, r_hi)
        return None, False
    inl = wts > 0
    res = res[inl]
    rms = float(np.sqrt(np.mean(res ** 2))) if inl.any() else math.inf
    used = np.zeros(len(pts), bool)
    used[np.flatnonzero(good)[inl]] = True
    edges = np.asarray(c)[None, :] + scale * pts + np.nan_to_num(off)[:, None] * nrm
    radial = radial_share(gy, gx, c, R, shown, stride=stride)
    if radial < MIN_RADIAL_SHARE or (radial < 1.0 and height < PARTIAL_SHARE_RIDGE):
        # a circle in a texture, not a reflection's limb
        logger.debug("limb fit: circle (%.1f, %.1f) r %.1f px refused: detail along the "
                     "radius in a share %.2f of the sectors, ridge %.2f", *c, R, radial,
                     height)
        return None, True
    rise = radial_rise(gy, gx, c, R, shown, stride=stride)
    if rise < MIN_RADIAL_RISE:
        # detail along the radius, but not squeezed toward the edge
        logger.debug("limb fit: circle (%.1f, %.1f) r %.1f px refused: a rise of %.2f",
                     *c, R, rise)
        return None, True
    return LimbFit(center_px=(float(c[0]), float(c[1])), radius_px=float(R),
                   energy_step=0.0, ridge_height=float(height),
                   step_coherence=_step_coherence(lum_s, c, scale, pts, nrm, good),
                   radial_share=radial, radial_rise=rise,
                   energy_center_px=(float(c[0]), float(c[1])), energy_radius_px=float(R),
                   points_used=int(used.sum()), points_total=len(pts),
                   residual_rms_px=rms, edge_points_px=edges[used],
                   used_index=np.flatnonzero(used), residuals_px=res), False
