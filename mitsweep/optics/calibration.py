"""Find the mirror in a photograph: its predicted outline, and a sub-pixel rim fit.

The setup predicts where the mirror's outline lands on the sensor, in millimetres from
the optical axis (:func:`predicted_outline`): the chief-ray image
(:mod:`mitsweep.optics.chief_ray`) of the mirror's rim, or of its limb where the camera
sees past the surface before the rim (a hemisphere), at the reference sensor distance
(mid-travel of the sweep, :mod:`mitsweep.optics.reference`). An untilted mirror's
outline is a circle about the axis; a tilted mirror's is not, and its axis point (the
image of the vertex) is not the outline's centre.

:func:`fit_rim` finds that outline in a photograph. The unknowns are where the axis is
(``center_px``, row and column) and a scale ``k`` of the outline about it, which absorbs
a wrong pixel pitch or lens–mirror distance:

1. *Coarse search* on a copy reduced so that the outline's radius is 32-64 px:
   the gradient's double-angle orientation field (sign-free: a rim may be brighter or
   darker than what surrounds it), of the luminance and of the local energy of fine
   detail (a reflection about as bright as what surrounds the mirror still differs
   from it in detail: the sweep focuses on the reflection, not on the surroundings),
   correlated by FFT with the outline's normals, for
   scales ``k`` within the plausible ±15% of the prediction (and, only when that finds
   no mirror, in ``[1/3, 3]``, to tell a wrong setup from a missing mirror). The score
   is the mean alignment times the square root of the outline's length (a mean over
   ~perimeter samples), so that a small outline on busy texture does not outscore the
   rim. At the best position, of the scale peaks within half the best score, the one
   nearest the predicted size is kept: a holder around the mirror is a concentric
   outline too, and the rim is the one the setup predicts.
2. *Refinement* at full resolution: along the outline's normal at each of N points,
   the intensity profile's derivative (one sign, the dominant one) gives a sub-pixel
   edge position as the peak of its lobe (a Gaussian fitted to its top,
   :func:`_gaussian_peak`), which is the mean chief-ray position of a defocused,
   breathing edge (a symmetric blur about each chief-ray image), so the fit lands on
   the mid-travel outline. The peak, not the lobe's centroid: where content of the
   reflection meets the rim (a bright banner whose far edge has the other sign) the
   lobe's flanks are not the blur's, and on Mitsuba renders of the tilted paraboloid
   its centroid moved the axis by 0.21-0.35 px, its peak by 0.05-0.18 px. Normal offsets are fitted by iteratively reweighted least
   squares (Tukey's biweight, scale from the median absolute deviation), so that
   edges of a mount, an arm crossing the rim or a reflection do not pull the fit.
   Vignetting and smooth illumination changes do not move a gradient's centroid.

What the photo does not show is left out: exact zeros (what a renderer skipped,
:func:`photo_void`) are filled from the nearest shown pixel, so the border of a render
cropped to the mirror's window is no edge, and outline points there are not asked for
one. The camera's roll about its axis can be fitted as a fourth unknown where the
outline shows it (a tilted mirror's; ``fit_roll``).

A photograph without the mirror gives few consistent edge points, or an outline that
is no clearer an edge than its surroundings (:func:`_edge_prominence`), or edges
scattered by more than :data:`MAX_RESIDUAL_RMS_PX` about it, and
:class:`CalibrationError` says so. The centre's standard error is reported; above
:data:`WARN_CENTRE_SE_PX` the calibration warns.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..config import Setup
from .chief_ray import chief_ray, image_point
from .placement import placement_of
from .pixels import optical_center_px
from .reference import reference_geometry

__all__ = ["CalibrationError", "RimOutline", "RimFit", "Calibration", "predicted_outline",
           "fit_rim", "calibrate_photo", "luminance", "photo_void", "PLAUSIBLE_SCALE",
           "WARN_SCALE"]

logger = logging.getLogger(__name__)

#: Largest relative difference between the measured and the predicted outline size
#: that a calibration accepts (a pitch or lens–mirror distance off by 15%).
PLAUSIBLE_SCALE = 0.15
#: Relative difference above which the calibration warns that the setup is off.
WARN_SCALE = 0.01
#: Smallest share of the outline points the photo shows that must show an edge.
MIN_INLIER_FRACTION = 0.4
#: Smallest share of those edges that the fitted outline must explain (the robust fit's
#: inliers): on the faint rim of a rendered tilted paraboloid (200 px, 64 spp) 45% of the
#: outline shows an edge above the noise, and 86% of those edges are inliers.
MIN_CONSISTENT_FRACTION = 0.6
#: Smallest ratio of the gradient on the fitted outline to the gradient beside it
#: (:func:`_edge_prominence`): a mirror's rim stands out, texture does not.
MIN_EDGE_PROMINENCE = 3.0
#: Share of the outline's points cut at each end of the mean |derivative| of
#: :func:`_edge_prominence`.
PROMINENCE_TRIM = 0.2
#: Gaussian smoothing (px) of the image the edge profiles are sampled on: it lowers
#: the noise; on a rim of radius R it moves the edge inward by only ~σ²/(2R).
PROFILE_SMOOTHING_PX = 1.2
#: Half-width (px) of the top of the derivative lobe fitted by a Gaussian to locate the
#: edge (:func:`_gaussian_peak`). Measured on Mitsuba sweep renders of the tilted
#: paraboloid (200-300 px, 64-128 spp, 8 renders): the lobe's centroid leaves the axis
#: 0.20-0.33 px off, a Gaussian over the lobe above half its peak 0.18-0.27, above 0.7
#: of it 0.13-0.23, over +-0.25 px 0.06-0.20, over +-0.5 px 0.05-0.18.
EDGE_PEAK_HALF_WIDTH_PX = 0.5
#: Edge contrast-to-noise ratio above which edges count as equally precise (the
#: limit is then the texture, not the noise).
MAX_EDGE_SNR = 30.0
#: Largest RMS normal residual (px) of the inliers of an accepted fit: an outline of
#: the wrong shape (the square border of a render cropped to the mirror's window, found
#: at +7..17% of the rim's size) leaves 1.8-2.0 px on the renders, the true rim of the
#: rendered tilted paraboloid 0.65-0.95 px (its weak edges scatter against the detailed
#: reflection).
MAX_RESIDUAL_RMS_PX = 1.5
#: Standard error (px) of the fitted centre (from the inliers' scatter) above which the
#: calibration warns that the centre is uncertain (the issue's bar on it is 0.25 px).
WARN_CENTRE_SE_PX = 0.25
#: Outline length (px) over which neighbouring edge points count as one independent
#: measurement (the profiles overlap in the smoothing and the rim's blur).
EDGE_CORRELATION_PX = 2.0
#: Scale (px) of the fine detail whose local energy is the coarse search's second cue.
TEXTURE_SCALE_PX = 1.0
#: Radius (px) of the outline in the reduced copy used for the coarse search (at least).
COARSE_RADIUS_PX = 32.0
#: Relative step of the scales searched coarsely (4%: ~1.3 px at 32 px).
COARSE_SCALE_STEP = 1.04
#: The wide band of scales searched when the plausible one finds no mirror, so that a
#: setup far off is reported as such, not as a photo without a mirror.
WIDE_SCALES = (1.0 / 3.0, 3.0)
#: Share of exact zeros (all channels) in a 5x5 neighbourhood from which a pixel is
#: outside the photo (:func:`photo_void`): what a renderer skipped (``mitsweep render``
#: writes only the mirror's window) is exactly zero, and stays half zero after a
#: sub-pixel shift (the negative ringing clips to 0); a photographed scene is not.
VOID_ZERO_SHARE = 0.4
#: Pixels added around the void: the ringing of a shifted window's border.
VOID_MARGIN_PX = 2
#: The roll is fitted when a radian of it moves the outline's points by more than this
#: share of its radius (RMS along the normals): never for a circle about the axis
#: (0), for the tilted paraboloid 0.30.
ROLL_OBSERVABLE = 0.01
#: Roll (degrees) above which the calibration warns: setups have no roll, so banks and
#: panoramas made from the calibrated setup are turned by it.
WARN_ROLL_DEG = 0.5


def _scales(lo: float, hi: float) -> np.ndarray:
    n = max(2, int(math.ceil(math.log(hi / lo) / math.log(COARSE_SCALE_STEP))) + 1)
    return np.geomspace(lo, hi, n)


class CalibrationError(ValueError):
    """The mirror was not found in the photo, or disagrees with the setup."""


@dataclass(frozen=True)
class RimOutline:
    """The mirror's predicted outline on the sensor.

    Attributes
    ----------
    uv : (N, 2) ndarray
        Outline points ``(u, v)``, mm from the optical axis (upright image: u right,
        v up), in order around the outline.
    normal_uv : (N, 2) ndarray
        Outward unit normals in the same frame.
    sensor_distance : float
        Sensor distance (mm) the outline is predicted for.
    on_rim : (N,) bool ndarray
        True where the point is the rim's image, False where it is the limb's.
    """

    uv: np.ndarray
    normal_uv: np.ndarray
    sensor_distance: float
    on_rim: np.ndarray

    def offsets_px(self, pitch: float) -> tuple[np.ndarray, np.ndarray]:
        """Points and outward normals as ``(drow, dcol)`` pixels from the axis, (N, 2)."""
        pts = np.stack([-self.uv[:, 1], self.uv[:, 0]], axis=-1) / pitch
        nrm = np.stack([-self.normal_uv[:, 1], self.normal_uv[:, 0]], axis=-1)
        return pts, nrm

    def equivalent_radius_px(self, pitch: float) -> float:
        """Radius (px) of the circle of the outline's area (the radius, for a circle)."""
        u, v = self.uv[:, 0], self.uv[:, 1]
        area = 0.5 * abs(np.dot(u, np.roll(v, -1)) - np.dot(v, np.roll(u, -1)))
        return math.sqrt(area / math.pi) / pitch


def _resample_closed(points: np.ndarray, n: int) -> np.ndarray:
    """``n`` points evenly spaced by arc length along a closed polyline (N, 2)."""
    closed = np.vstack([points, points[:1]])
    seg = np.linalg.norm(np.diff(closed, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    t = np.linspace(0.0, s[-1], n, endpoint=False)
    return np.stack([np.interp(t, s, closed[:, 0]), np.interp(t, s, closed[:, 1])], axis=-1)


def predicted_outline(setup: Setup, *, sensor_distance: float | None = None,
                      n_points: int = 1440) -> RimOutline:
    """The outline of the mirror's image predicted by the setup.

    Parameters
    ----------
    setup : mitsweep.config.Setup
    sensor_distance : float, optional
        Lens–sensor distance, mm (default: the reference distance, mid-travel of the
        sweep, the distance whose image the centroid of a sweep photo's rim blur is).
    n_points : int
        Points along the outline (evenly spaced by arc length).

    Returns
    -------
    RimOutline

    Notes
    -----
    Along each meridian φ of the mirror the last point the lens sees is the rim, or
    the limb ``n·r̂ = 0`` where that comes first (found by bisection); the outline is
    the chief-ray image of those points. That is exact for an untilted mirror (the
    image radius grows with ρ up to the limb) and wherever the rim is visible all
    round (the paper's mirrors, the tilted paraboloid included).
    """
    if sensor_distance is None:
        sensor_distance = reference_geometry(setup).sensor_distance
    placement = placement_of(setup.mirror)
    rim = setup.mirror.rim_radius
    phi = np.linspace(0.0, 2.0 * math.pi, 4 * n_points, endpoint=False)

    def cos_inc(rho):
        surf = placement.surface(rho * np.cos(phi), rho * np.sin(phi))
        return chief_ray(placement, surf).cos_incidence

    rho_edge = np.full(phi.shape, rim)
    hidden = ~(cos_inc(rho_edge) > 0)
    if np.any(hidden):  # the limb comes before the rim on these meridians: bisect
        lo, hi = np.zeros(phi.shape), np.full(phi.shape, rim)
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            vis = cos_inc(mid) > 0
            lo, hi = np.where(vis, mid, lo), np.where(vis, hi, mid)
        rho_edge = np.where(hidden, lo, rim)
    surf = placement.surface(rho_edge * np.cos(phi), rho_edge * np.sin(phi))
    u, v = image_point(chief_ray(placement, surf), sensor_distance)
    dense = np.stack([u, v], axis=-1)
    uv = _resample_closed(dense, n_points)
    tangent = np.roll(uv, -1, axis=0) - np.roll(uv, 1, axis=0)
    normal = np.stack([tangent[:, 1], -tangent[:, 0]], axis=-1)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    centroid = uv.mean(axis=0)
    normal *= np.where(np.sum((uv - centroid) * normal, axis=-1) < 0, -1.0, 1.0)[:, None]
    # Which resampled points are rim (not limb): nearest dense sample's flag.
    nearest = np.argmin(np.linalg.norm(dense[None, ::4] - uv[:, None], axis=-1), axis=1)
    return RimOutline(uv=uv, normal_uv=normal, sensor_distance=float(sensor_distance),
                      on_rim=~hidden[::4][nearest])


def luminance(image: np.ndarray) -> np.ndarray:
    """Linear luminance (H, W) float64 of an (H, W) or (H, W, 3) linear image
    (Rec. 709 weights; a grey image is returned as is)."""
    a = np.asarray(image, dtype=np.float64)
    if a.ndim == 2:
        return a
    return a[..., :3] @ np.array([0.2126, 0.7152, 0.0722])


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


def photo_void(image: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels outside what the photo shows, the renderer's skipped pixels.

    Where at least :data:`VOID_ZERO_SHARE` of a 5x5 neighbourhood is exactly zero in
    every channel, in regions wider than 3 px, grown by :data:`VOID_MARGIN_PX`. A render
    cropped to the mirror's window (black from 8 px outside the rim) has a strong
    straight edge beside the rim there, which is not the photo's content: the rim fit
    treats the void as unknown (:func:`fit_rim`). A photo without exact zeros has none.
    """
    from scipy.ndimage import binary_dilation, binary_opening, uniform_filter

    a = np.asarray(image)
    zero = (a == 0) if a.ndim == 2 else np.all(a == 0, axis=-1)
    if not zero.any():
        return zero
    void = uniform_filter(zero.astype(np.float64), 5, mode="nearest") >= VOID_ZERO_SHARE
    void = binary_opening(void, np.ones((3, 3), bool), iterations=1)
    if VOID_MARGIN_PX > 0 and void.any():
        void = binary_dilation(void, np.ones((3, 3), bool), iterations=VOID_MARGIN_PX)
    return void


def _fill_void(lum: np.ndarray, void: np.ndarray) -> np.ndarray:
    """``lum`` with each void pixel set to its nearest shown pixel's value: the void's
    border is then no edge (the profiles and orientation fields see nothing there)."""
    from scipy.ndimage import distance_transform_edt

    if not void.any() or void.all():
        return lum
    _, (ii, jj) = distance_transform_edt(void, return_indices=True)
    return lum[ii, jj]


def _smooth(img: np.ndarray, sigma: float) -> np.ndarray:
    from scipy.ndimage import gaussian_filter

    return gaussian_filter(img, sigma, mode="nearest") if sigma > 0 else img


def _reduce(img: np.ndarray, factor: int) -> np.ndarray:
    if factor <= 1:
        return img
    H, W = (img.shape[0] // factor) * factor, (img.shape[1] // factor) * factor
    return img[:H, :W].reshape(H // factor, factor, W // factor, factor).mean(axis=(1, 3))


def _texture_energy(lum: np.ndarray) -> np.ndarray:
    """Local RMS (H, W) of the image's fine detail: the high-pass at
    :data:`TEXTURE_SCALE_PX`, its square smoothed over the same scale."""
    detail = lum - _smooth(lum, TEXTURE_SCALE_PX)
    return np.sqrt(_smooth(detail * detail, TEXTURE_SCALE_PX))


def _coarse_search(lum: np.ndarray, pts: np.ndarray, nrm: np.ndarray, scales: np.ndarray):
    """Best ``(center (row, col), scale)`` of the outline in full-resolution pixels."""
    from scipy.fft import irfft2, next_fast_len, rfft2

    radius = float(np.sqrt(np.mean(np.sum(pts ** 2, axis=1))))
    factor = max(1, int(radius / COARSE_RADIUS_PX))
    j1 = j2 = 0.0
    # Two cues, each an orientation field of unit strength at most: the luminance, and
    # the local texture energy, where a rim of little contrast (a reflection as bright
    # as what surrounds the mirror, as on the rendered tilted paraboloid) still shows:
    # the reflection is detailed, what surrounds it far out of focus.
    for cue in (lum, _texture_energy(lum)):
        small = _smooth(_reduce(cue, factor), 1.0)
        gy, gx = np.gradient(small)
        mag = np.hypot(gx, gy)
        # Sign-free orientation field, magnitude compressed so that a few very bright
        # edges (a lamp in the reflection) do not outweigh the rim.
        cap = np.percentile(mag, 99.5) + 1e-30
        w = np.minimum(mag, cap) / (mag * mag + 1e-300) / cap  # |j| = min(|g|, cap)/cap
        j1 = j1 + (gx * gx - gy * gy) * w
        j2 = j2 + (2.0 * gx * gy) * w
    H, W = small.shape
    # Template normals as image-axis angles: gradient (gy, gx) along (drow, dcol).
    c2 = nrm[:, 1] ** 2 - nrm[:, 0] ** 2
    s2 = 2.0 * nrm[:, 0] * nrm[:, 1]
    extent = int(np.ceil(np.abs(pts).max() * scales[-1] / factor)) + 2
    shape = (next_fast_len(H + 2 * extent), next_fast_len(W + 2 * extent))
    F1, F2 = rfft2(j1, shape), rfft2(j2, shape)
    best = None
    per_scale = []
    for k in scales:
        p = pts * k / factor
        flat = (np.round(p[:, 0]).astype(int) % shape[0]) * shape[1] \
            + np.round(p[:, 1]).astype(int) % shape[1]
        t1 = np.bincount(flat, weights=c2, minlength=shape[0] * shape[1]).reshape(shape)
        t2 = np.bincount(flat, weights=s2, minlength=shape[0] * shape[1]).reshape(shape)
        score = irfft2(F1 * np.conj(rfft2(t1)) + F2 * np.conj(rfft2(t2)), shape)[:H, :W]
        # Mean alignment along the outline, times the square root of its length: the
        # significance of a mean over ~perimeter independent samples, so that a small
        # outline on busy texture does not outscore the rim.
        score *= math.sqrt(k) / len(p)
        i = int(np.argmax(score))
        per_scale.append(score)
        if best is None or score.flat[i] > best[0]:
            best = (float(score.flat[i]), i, k)
    top, idx, _ = best
    row, col = np.unravel_index(idx, (H, W))
    # At that position: of the scale peaks within half the best, the nearest to k = 1.
    local = np.array([s[max(0, row - 1):row + 2, max(0, col - 1):col + 2].max()
                      for s in per_scale])
    peaks = [j for j in range(len(local))
             if local[j] >= 0.5 * top and (j == 0 or local[j] >= local[j - 1])
             and (j == len(local) - 1 or local[j] >= local[j + 1])]
    j = min(peaks, key=lambda q: abs(math.log(scales[q]))) if peaks else \
        int(np.argmax(local))
    s = per_scale[j]
    win = s[max(0, row - 2):row + 3, max(0, col - 2):col + 3]
    dr, dc = np.unravel_index(int(np.argmax(win)), win.shape)
    row, col = max(0, row - 2) + dr, max(0, col - 2) + dc
    centre = ((row + 0.5) * factor - 0.5, (col + 0.5) * factor - 0.5)
    return centre, float(scales[j]), float(local[j])


def _edge_offsets(lum_s: np.ndarray, centre, scale, pts, nrm, half: float, *,
                  outermost: bool = False):
    """Sub-pixel edge offset along each normal (NaN where no edge), and its contrast.

    The edge is the top of the lobe of the dominant-sign derivative around its highest
    peak (:func:`_gaussian_peak`; the lobe's centroid where its top cannot be fitted), or,
    with ``outermost``, around the outermost peak at least half as high: the rim is
    the outer boundary of the mirror's content, whose own edges (sharp: the reflection
    is what the sweep focuses on) lie inside it, while what surrounds the mirror is
    usually far out of focus."""
    from scipy.ndimage import map_coordinates

    step = 0.25
    t = np.arange(-half, half + step / 2, step)
    base = np.asarray(centre)[None, :] + scale * pts
    coords = base[:, None, :] + t[None, :, None] * nrm[:, None, :]
    H, W = lum_s.shape
    inside = np.all((coords[..., 0] >= 0) & (coords[..., 0] <= H - 1)
                    & (coords[..., 1] >= 0) & (coords[..., 1] <= W - 1), axis=1)
    prof = map_coordinates(lum_s, [coords[..., 0].ravel(), coords[..., 1].ravel()],
                           order=1, mode="nearest").reshape(coords.shape[:2])
    d = np.gradient(prof, step, axis=1)
    sign = np.sign(np.sum(d, axis=1, keepdims=True))
    sign[sign == 0] = 1.0
    ds = d * sign
    peak = ds.max(axis=1, keepdims=True)
    # Centroid of the dominant-sign derivative's lobe around its peak, above a fifth of
    # the peak: the mean edge position of a symmetric blur, without the texture's small
    # wiggles or a separate edge of the content nearby.
    above = ds > 0.2 * peak
    k = np.arange(ds.shape[1])[None, :]
    at = np.argmax(ds, axis=1)[:, None]
    if outermost:
        prev = np.pad(ds[:, :-1], ((0, 0), (1, 0)), constant_values=-np.inf)
        nxt = np.pad(ds[:, 1:], ((0, 0), (0, 1)), constant_values=-np.inf)
        high = (ds >= prev) & (ds >= nxt) & (ds >= 0.5 * peak)
        at = (ds.shape[1] - 1 - np.argmax(high[:, ::-1], axis=1))[:, None]
    gap_left = np.maximum.accumulate(np.where(~above, k, -1), axis=1)
    gap_right = np.minimum.accumulate(np.where(~above, k, ds.shape[1])[:, ::-1], axis=1)[:, ::-1]
    left = np.take_along_axis(gap_left, at, axis=1)
    right = np.take_along_axis(gap_right, at, axis=1)
    wgt = np.where(above & (k > left) & (k < right), ds, 0.0)
    total = wgt.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        off = (wgt * t[None, :]).sum(axis=1) / total
    # The edge is the peak of the derivative lobe (a Gaussian through its top,
    # :func:`_gaussian_peak`); the lobe's centroid is the fallback where the top is too
    # narrow to fit.
    peak_at = _gaussian_peak(ds, t, at[:, 0], above & (k > left) & (k < right))
    off = np.where(np.isfinite(peak_at), peak_at, off)
    contrast = np.abs(prof[:, -1] - prof[:, 0])
    step_size = total * step  # the integrated derivative: the edge's contrast
    off = np.where(inside & (total > 0), off, np.nan)
    return off, step_size, contrast


def _gaussian_peak(ds: np.ndarray, t: np.ndarray, at: np.ndarray,
                   lobe: np.ndarray) -> np.ndarray:
    """(N,) position along ``t`` of each profile's derivative peak: the vertex of the
    parabola fitted (least squares) to ``log ds`` over the samples of the ``lobe``
    within :data:`EDGE_PEAK_HALF_WIDTH_PX` of its peak sample ``at``, i.e. a Gaussian
    through the top of the lobe, kept within those samples (a flat or one-sided top
    leaves the peak sample); NaN where the lobe has fewer than 3 samples there.

    The top of a blurred step's derivative is where the step is, whatever the step's
    size (a symmetric blur); its flanks are where content next to the rim (a reflection's
    bright banner ending at the rim, whose far edge has the opposite sign) adds to or
    takes from the lobe, which moves a centroid over the whole lobe but not its top."""
    n = len(ds)
    pk = ds[np.arange(n), at]
    x = t[None, :] - t[at][:, None]  # about the peak sample: well conditioned
    use = lobe & (np.abs(x) <= EDGE_PEAK_HALF_WIDTH_PX + 1e-9) & (ds > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        y = np.where(use, np.log(np.where(use, ds, 1.0) / pk[:, None]), 0.0)
    w = use.astype(np.float64)
    s = [np.sum(w * x ** p, axis=1) for p in range(5)]
    r = [np.sum(w * y * x ** p, axis=1) for p in range(3)]
    # normal equations of y = a x² + b x + c
    M = np.stack([np.stack([s[4], s[3], s[2]], -1), np.stack([s[3], s[2], s[1]], -1),
                  np.stack([s[2], s[1], s[0]], -1)], -2)
    R = np.stack([r[2], r[1], r[0]], -1)
    out = np.full(n, np.nan)
    ok = (s[0] >= 3) & np.isfinite(pk) & (pk > 0)
    if ok.any():
        det = np.linalg.det(M[ok])
        good = np.flatnonzero(ok)[np.abs(det) > 1e-18]
        if len(good):
            a, b, _ = np.linalg.solve(M[good], R[good][..., None])[..., 0].T
            with np.errstate(divide="ignore", invalid="ignore"):
                vx = np.where(a < 0, -b / (2.0 * a), np.nan)
            span = np.max(np.where(use[good], np.abs(x[good]), 0.0), axis=1)
            vx = np.clip(np.nan_to_num(vx, nan=0.0), -span, span)
            out[good] = t[at[good]] + vx
    return out


def _edge_prominence(lum_s, centre, scale, pts, nrm, half: float, radius: float) -> float:
    """How much stronger the image's gradient is on the fitted outline than beside it:
    the |derivative| across the outline, averaged over the outline's points, within
    ``half``/2 of it, over its median from 2 ``half`` to 4 ``half`` on both sides (a
    rim: several; texture: about 1).

    The average over points is a trimmed mean (:data:`PROMINENCE_TRIM` cut at each
    end): a strong edge beside part of the outline only (the black border of a render
    cropped to the mirror's window 8 px outside the rim, a holder's arm, a bright
    object in the reflection) would otherwise raise the "beside" level of the whole
    outline. On Mitsuba sweep renders of the paraboloid, cropped to the mirror's
    window, it raises the prominence from 3.8-5.0 to 5.9-10.4; on a photo without a
    mirror it stays below 2."""
    from scipy.ndimage import map_coordinates
    from scipy.stats import trim_mean

    reach = min(4.0 * half, 0.5 * radius)
    step = 0.25
    t = np.arange(-reach, reach + step / 2, step)
    coords = np.asarray(centre)[None, None, :] + scale * pts[:, None, :] \
        + t[None, :, None] * nrm[:, None, :]
    H, W = lum_s.shape
    inside = np.all((coords[..., 0] >= 0) & (coords[..., 0] <= H - 1)
                    & (coords[..., 1] >= 0) & (coords[..., 1] <= W - 1), axis=1)
    if not inside.any():
        return 0.0
    c = coords[inside]
    prof = map_coordinates(lum_s, [c[..., 0].ravel(), c[..., 1].ravel()], order=1,
                           mode="nearest").reshape(c.shape[:2])
    mean_abs = trim_mean(np.abs(np.gradient(prof, step, axis=1)), PROMINENCE_TRIM, axis=0)
    on = mean_abs[np.abs(t) <= 0.5 * half].max()
    beside = np.median(mean_abs[np.abs(t) >= min(2.0 * half, 0.5 * reach)])
    return float(on / (beside + 1e-30))


def _noise_sigma(lum: np.ndarray, shown: np.ndarray | None = None) -> float:
    """Robust per-pixel noise estimate (MAD of the diagonal second difference), over
    the 2x2 blocks the photo shows (all of them by default)."""
    d = lum[1:, 1:] - lum[:-1, 1:] - lum[1:, :-1] + lum[:-1, :-1]
    if shown is not None:
        block = shown[1:, 1:] & shown[:-1, 1:] & shown[1:, :-1] & shown[:-1, :-1]
        if block.any():
            d = d[block]
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / 2.0)


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


def _centre_standard_error(A: np.ndarray, residuals: np.ndarray, length_px: float) -> float:
    """Standard error (px) of the fitted centre (the larger of row and column): the
    least-squares covariance ``s² (AᵀA)⁻¹`` of the inliers' design ``A`` (M, 3) and
    residuals, with the points counted as ``length_px / EDGE_CORRELATION_PX``
    independent measurements, not M."""
    m = len(residuals)
    if m <= A.shape[1]:
        return math.inf
    s2 = float(np.sum(residuals ** 2)) / (m - A.shape[1])
    independent = max(A.shape[1] + 1.0, min(m, length_px / EDGE_CORRELATION_PX))
    cov = s2 * np.linalg.pinv(A.T @ A) * (m / independent)
    return float(math.sqrt(max(cov[0, 0], cov[1, 1])))


def fit_rim(image: np.ndarray, outline: RimOutline, pitch: float, *,
            scale_range: tuple[float, float] = (1 - PLAUSIBLE_SCALE, 1 + PLAUSIBLE_SCALE),
            max_iterations: int = 30, edge_half_width_px: float | None = None,
            fit_roll: bool = False) -> RimFit:
    """Find the predicted outline in a photograph (see the module docstring).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        Linear photograph.
    outline : RimOutline
        The setup's prediction (:func:`predicted_outline`).
    pitch : float
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

    Returns
    -------
    RimFit

    Raises
    ------
    CalibrationError
        When too few outline points show a consistent edge or the residual is large:
        the photo does not show the mirror the setup describes.
    """
    lum = luminance(image)
    if lum.ndim != 2 or min(lum.shape) < 8:
        raise CalibrationError(f"the photo must be an image of at least 8x8 pixels, got "
                               f"shape {np.shape(image)}")
    pts, nrm = outline.offsets_px(pitch)
    radius = outline.equivalent_radius_px(pitch)
    if radius < 8:
        raise CalibrationError(f"the setup predicts a mirror image of radius {radius:.3g} px "
                               f"at pitch {pitch:g} mm: too small to calibrate on")
    scales = _scales(*scale_range)
    void = photo_void(image)
    shown = ~void
    if void.any() and shown.any():
        filled = _fill_void(lum, void)
        centre, scale, coarse_score = _coarse_search(filled, pts, nrm, scales)
        hidden = _in_void(void, centre, scale, pts)
        if hidden.mean() > 1.0 - MIN_INLIER_FRACTION:
            # exact zeros around most of the rim: a clipped black background, not a
            # renderer's skipped pixels; the rim's edge against it is real
            logger.info("%.0f%% of the outline borders exact zeros: not treated as "
                        "outside the photo", 100 * hidden.mean())
            void[:] = False
            shown[:] = True
            centre, scale, coarse_score = _coarse_search(lum, pts, nrm, scales)
        else:
            logger.info("%d px of exact zeros treated as outside the photo (%.0f%% of the "
                        "outline)", int(void.sum()), 100 * hidden.mean())
            lum = filled
    else:
        centre, scale, coarse_score = _coarse_search(lum, pts, nrm, scales)
    logger.info("coarse rim search: centre (%.1f, %.1f) px, scale %.3f (score %.3g)",
                *centre, scale, coarse_score)
    half = edge_half_width_px or max(4.0, 0.015 * radius * scale)
    lum_s = _smooth(lum, PROFILE_SMOOTHING_PX)
    sigma = _noise_sigma(lum, shown)
    n = len(pts)
    off = np.full(n, np.nan)
    used = np.zeros(n, bool)
    rms = math.inf
    it = 0
    # The camera's roll about its axis turns the outline about the axis point: a circle
    # about the axis does not show it, a tilted mirror's outline does.
    pts0, nrm0 = pts, nrm
    roll = 0.0
    fit_roll = bool(fit_roll) and float(np.sqrt(np.mean(_roll_column(pts, nrm) ** 2))) \
        > ROLL_OBSERVABLE * radius
    # The first window covers the coarse search's steps: a reduced pixel and a scale step.
    factor = max(1, int(radius / COARSE_RADIUS_PX))
    search = max(half, 1.5 * factor + (COARSE_SCALE_STEP - 1) * radius * scale)
    for it in range(1, max_iterations + 1):
        pts, nrm = _rotated(pts0, roll), _rotated(nrm0, roll)
        off, strength, _ = _edge_offsets(lum_s, centre, scale, pts, nrm, search,
                                         outermost=search <= half)
        # An edge must rise above the noise (a step of 3 σ of one pixel) to count; only
        # the outline's points the photo shows (not in its void) are asked for one.
        seen = ~_in_void(void, centre, scale, pts)
        n_seen = int(seen.sum())
        good = np.isfinite(off) & (strength > 3.0 * sigma + 1e-12) & seen
        if good.sum() < max(8, MIN_INLIER_FRACTION * n_seen):
            raise CalibrationError(
                f"no visible mirror: only {int(good.sum())} of {n} points of the predicted "
                f"outline (radius {radius:.1f} px at pitch {pitch:g} mm) show an edge; "
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
        unc = 1.0 / snr
        wts = np.ones(len(b))
        for _ in range(10):
            sw = np.sqrt(wts) / unc
            x, *_ = np.linalg.lstsq(A * sw[:, None], b * sw, rcond=None)
            z = (b - A @ x) / unc
            s = 1.4826 * np.median(np.abs(z - np.median(z))) + 1e-6
            u = z / (4.685 * s)
            wts = np.where(np.abs(u) < 1, (1 - u * u) ** 2, 0.0)
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
        if np.abs(x[:2]).max() < 1e-3 and max(abs(x[2]), abs(d_roll)) * radius < 1e-3:
            break
    pts, nrm = _rotated(pts0, roll), _rotated(nrm0, roll)
    n_used = int(used.sum())
    prominence = _edge_prominence(lum_s, centre, scale, pts, nrm, half, radius * scale)
    logger.info("rim fit: %d of %d points, rms %.3f px, edge prominence %.2f after %d "
                "passes", n_used, n, rms, prominence, it)
    if prominence < MIN_EDGE_PROMINENCE:
        raise CalibrationError(
            f"no visible mirror: the best outline found (radius {radius * scale:.1f} px) is "
            f"no clearer an edge than its surroundings (prominence {prominence:.2f}, need "
            f"{MIN_EDGE_PROMINENCE:g}); check that the photo shows the mirror of this setup")
    centre_se = _centre_standard_error(A[inl], res[inl], n_used / n * radius * scale
                                       * 2.0 * math.pi) if inl.any() else math.inf
    logger.info("rim fit: centre standard error %.3f px", centre_se)
    n_edges = int(good.sum())
    if n_used < MIN_CONSISTENT_FRACTION * n_edges or rms > MAX_RESIDUAL_RMS_PX:
        raise CalibrationError(
            f"no visible mirror: the best outline found fits {n_used} of the {n_edges} edge "
            f"points on its {n} with rms {rms:.2f} px (need {MIN_CONSISTENT_FRACTION:.0%} "
            f"within {MAX_RESIDUAL_RMS_PX:g} px); check that the photo shows the mirror of "
            f"this setup")
    edges = np.asarray(centre)[None, :] + scale * pts + off[:, None] * nrm
    return RimFit(center_px=(float(centre[0]), float(centre[1])), scale=float(scale),
                  points_used=n_used, points_total=n, residual_rms_px=rms,
                  edge_points_px=edges[used], iterations=it, center_se_px=centre_se,
                  roll_deg=math.degrees(roll) if fit_roll else None)


@dataclass(frozen=True)
class Calibration:
    """A photo's calibration against a setup (see :func:`calibrate_photo`)."""

    fit: RimFit
    image_shape: tuple[int, int]
    pixel_pitch: float
    predicted_radius_px: float
    rim_radius_px: float
    center_offset_px: tuple[float, float]
    implied_pixel_pitch: float
    implied_vertex_distance: float | None
    sensor_distance: float
    warnings: list = field(default_factory=list)

    @property
    def center_px(self) -> tuple[float, float]:
        return self.fit.center_px

    @property
    def radius_ratio(self) -> float:
        return self.rim_radius_px / self.predicted_radius_px

    def calibrated_setup(self, setup: Setup) -> Setup:
        """The setup for this camera and photo: resolution, pitch, centre offset."""
        from ..config import Sensor

        H, W = self.image_shape
        return replace(setup, sensor=Sensor(resolution=(W, H), pixel_pitch=self.pixel_pitch,
                                            center_offset_px=self.center_offset_px))

    def as_dict(self) -> dict:
        return {"center_px": list(self.center_px),
                "center_offset_px": list(self.center_offset_px),
                "image_shape": list(self.image_shape),
                "pixel_pitch_mm": self.pixel_pitch,
                "rim_radius_px": self.rim_radius_px,
                "predicted_rim_radius_px": self.predicted_radius_px,
                "radius_ratio": self.radius_ratio,
                "implied_pixel_pitch_mm": self.implied_pixel_pitch,
                "implied_vertex_distance_mm": self.implied_vertex_distance,
                "reference_sensor_distance_mm": self.sensor_distance,
                "points_used": self.fit.points_used, "points_total": self.fit.points_total,
                "residual_rms_px": self.fit.residual_rms_px,
                "center_standard_error_px": self.fit.center_se_px,
                "roll_deg": self.fit.roll_deg,
                "warnings": list(self.warnings)}


def _implied_vertex_distance(setup, pitch: float, radius_px: float) -> float | None:
    """The lens–vertex distance (mm) at which the setup predicts ``radius_px``, the
    rest of the setup (pitch, lens, sweep settings) kept; None when no distance within
    20% does. The reference sensor distance follows the mirror: it is computed at the
    setup's distance and at the first guess, and interpolated in between (the sweep
    moves smoothly with the mirror)."""
    from scipy.optimize import brentq

    from ..config import Mirror, SetupError

    m = setup.mirror

    def moved(vd: float):
        return replace(setup, mirror=Mirror(kind=m.kind, radius=m.radius, conic=m.conic,
                                            rim_radius=m.rim_radius, vertex_distance=vd,
                                            tilt_deg=m.tilt_deg, aspheric=m.aspheric))

    try:
        vd0, i0 = m.vertex_distance, reference_geometry(setup).sensor_distance
        r0 = predicted_outline(setup, sensor_distance=i0, n_points=360)
        guess = vd0 * r0.equivalent_radius_px(pitch) / radius_px  # radius goes as ~1/distance
        i1 = reference_geometry(moved(guess)).sensor_distance
    except (SetupError, ValueError) as exc:
        logger.info("no implied lens-mirror distance: %s", exc)
        return None
    slope = (i1 - i0) / (guess - vd0) if guess != vd0 else 0.0

    def excess(vd: float) -> float:
        try:
            i = i0 + slope * (vd - vd0)
            out = predicted_outline(moved(vd), sensor_distance=i, n_points=360)
            return out.equivalent_radius_px(pitch) - radius_px
        except (SetupError, ValueError):
            return math.nan

    for width in (0.01, 0.05, 0.2):
        lo = max(guess * (1 - width), setup.lens.focal_length * 1.05)
        hi = guess * (1 + width)
        flo, fhi = excess(lo), excess(hi)
        if math.isfinite(flo) and math.isfinite(fhi) and flo * fhi <= 0:
            return float(brentq(excess, lo, hi, xtol=1e-3))
    return None


def calibrate_photo(image: np.ndarray, setup: Setup, *, pixel_pitch: float | None = None,
                    plausible_scale: float = PLAUSIBLE_SCALE,
                    fit_roll: bool = False) -> Calibration:
    """Calibrate a photograph of the setup's mirror: centre, rim size, what it implies.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        Linear photograph (e.g. :attr:`mitsweep.io.camera.CameraImage.data`).
    setup : mitsweep.config.Setup
    pixel_pitch : float, optional
        The photo's pitch, mm (default: the setup's).
    plausible_scale : float
        Largest accepted relative difference between the measured and predicted
        outline sizes.
    fit_roll : bool
        Fit the camera's roll too (tilted mirrors), see :func:`fit_rim`.

    Returns
    -------
    Calibration

    Raises
    ------
    CalibrationError
        No mirror found, or one whose size disagrees with the setup by more than
        ``plausible_scale`` (the message says the pitch or distance it would imply).
    """
    pitch = float(pixel_pitch or setup.sensor.pixel_pitch)
    outline = predicted_outline(setup)
    predicted = outline.equivalent_radius_px(pitch)
    try:
        fit = fit_rim(image, outline, pitch,
                      scale_range=(1 - plausible_scale, 1 + plausible_scale),
                      fit_roll=fit_roll)
    except CalibrationError as within:
        try:  # a mirror far off the predicted size is a wrong setup, not a missing mirror
            fit = fit_rim(image, outline, pitch, scale_range=WIDE_SCALES, fit_roll=fit_roll)
        except CalibrationError:
            raise within from None
        if abs(fit.scale - 1.0) <= plausible_scale:  # found on the second look after all
            logger.info("rim found in the wide search: %s", within)
    measured = predicted * fit.scale
    shape = (int(np.shape(image)[0]), int(np.shape(image)[1]))
    r0, c0 = optical_center_px(shape)
    offset = (fit.center_px[0] - r0, fit.center_px[1] - c0)
    implied_pitch = pitch / fit.scale
    if abs(fit.scale - 1.0) > plausible_scale:
        raise CalibrationError(
            f"implausible calibration: the mirror's rim measures {measured:.1f} px, the setup "
            f"predicts {predicted:.1f} px ({100 * (fit.scale - 1):+.1f}%, more than "
            f"{100 * plausible_scale:.0f}%); it implies a pixel pitch of "
            f"{implied_pitch:.5g} mm (setup {pitch:g} mm): check sensor.pixel_pitch and "
            f"mirror.vertex_distance")
    implied_vd = _implied_vertex_distance(setup, pitch, measured)
    warnings = []
    if abs(fit.scale - 1.0) > WARN_SCALE:
        vd = f"{implied_vd:.2f}" if implied_vd is not None else "?"
        warnings.append(
            f"rim radius {measured:.2f} px differs from the setup's {predicted:.2f} px by "
            f"{100 * (fit.scale - 1):+.2f}%: the pixel pitch would be {implied_pitch:.5g} mm "
            f"(setup {pitch:g}) or the lens-mirror distance {vd} mm "
            f"(setup {setup.mirror.vertex_distance:g})")
        if not outline.on_rim.any():
            # A hemisphere's outline is its limb, seen at grazing incidence, where the
            # reflection continues what lies behind the mirror: a render shows no edge
            # there (the sphere at 200 px: the fit found the boards' reflection 14.7%
            # inside, reflected rays at 114 deg), so the size says nothing of the pitch.
            warnings.append(
                "the outline is the mirror's limb (grazing reflection), which shows no "
                "edge where the reflection continues the background behind the mirror: "
                "the fitted outline may be an edge inside the reflection, not the limb, "
                "and its size then says nothing of the pitch or the distance")
    if fit.center_se_px > WARN_CENTRE_SE_PX:
        warnings.append(
            f"the rim is a faint edge: its {fit.points_used} edge points scatter by "
            f"{fit.residual_rms_px:.2f} px RMS, which leaves the centre uncertain by "
            f"{fit.center_se_px:.2f} px")
    if fit.roll_deg is not None and abs(fit.roll_deg) > WARN_ROLL_DEG:
        warnings.append(
            f"the camera is rolled by {fit.roll_deg:+.2f} deg about its axis; setups have no "
            f"roll, so banks and panoramas of the calibrated setup are turned by it")
    H, W = shape
    if not (0 <= fit.center_px[0] <= H - 1 and 0 <= fit.center_px[1] <= W - 1):
        warnings.append("the mirror's axis lies outside the photo")
    for w in warnings:
        logger.warning("%s", w)
    return Calibration(fit=fit, image_shape=shape, pixel_pitch=pitch,
                       predicted_radius_px=predicted, rim_radius_px=measured,
                       center_offset_px=offset, implied_pixel_pitch=implied_pitch,
                       implied_vertex_distance=implied_vd,
                       sensor_distance=outline.sensor_distance, warnings=warnings)
