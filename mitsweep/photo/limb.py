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
random sign whose azimuthal mean cancels: a sign-agnostic edge (the derivative lobe's
peak, :func:`mitsweep.photo.edges.edge_offsets`) searched within a pixel and a half of
that circle, fitted robustly (:func:`mitsweep.photo.robust.tukey_lstsq`), places it to a
fraction of a pixel. Measured in ``scripts/limb_study.py``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .edges import edge_offsets
from .image import smooth
from .robust import tukey_lstsq

__all__ = ["LimbFit", "fit_limb", "energy_map", "LIMB_SMOOTHING_PX", "LIMB_HALF_WIDTH_PX",
           "LIMB_ANNULUS_PX", "MIN_ENERGY_STEP"]

#: Gaussian smoothing (px) of the luminance the sign-agnostic step is located on.
LIMB_SMOOTHING_PX = 1.0
#: Half-width (px) of the search for the step along each normal, about the circle the
#: energy step gives (that circle is within ~1 px of the limb).
LIMB_HALF_WIDTH_PX = 1.5
#: Half-width (px) of the annulus over which the energy step is fitted (at least; 6% of
#: the radius on large images).
LIMB_ANNULUS_PX = 6.0
#: Smallest drop of the mean log energy across the limb (inside minus outside, natural
#: log) that counts as a limb.
MIN_ENERGY_STEP = 0.25


@dataclass(frozen=True)
class LimbFit:
    """A limb found: centre ``(row, col)`` and radius (px); ``energy_step`` the drop of
    the log fine-detail energy across it; ``energy_centre_px``/``energy_radius_px`` the
    energy step's circle (stage 1); ``points_used`` of ``points_total`` normals were the
    sign-agnostic step's inliers (``used_index`` into the outline's points, their normal
    residuals ``residuals_px``), with RMS residual ``residual_rms_px``."""

    center_px: tuple[float, float]
    radius_px: float
    energy_step: float
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
    tenth of the median ``d²`` (so that flat patches do not dominate)."""
    d = lum[1:, 1:] - lum[:-1, 1:] - lum[1:, :-1] + lum[:-1, :-1]
    d2 = d * d
    eps = 0.1 * float(np.median(d2)) + 1e-30
    return np.log(d2 + eps), eps


def _radial_profile(e, centre, r_lo, r_hi, step=0.5, shown=None):
    H, W = e.shape
    c0 = max(int(centre[0] - r_hi - 2), 0), min(int(centre[0] + r_hi + 3), H)
    c1 = max(int(centre[1] - r_hi - 2), 0), min(int(centre[1] + r_hi + 3), W)
    rows, cols = np.mgrid[c0[0]:c0[1], c1[0]:c1[1]]
    r = np.hypot(rows + 0.5 - centre[0], cols + 0.5 - centre[1])
    sub = e[c0[0]:c0[1], c1[0]:c1[1]]
    ok = (r >= r_lo) & (r < r_hi)
    if shown is not None:
        ok &= shown[c0[0]:c0[1], c1[0]:c1[1]]
    bins = np.arange(r_lo, r_hi + step, step)
    idx = np.digitize(r[ok], bins) - 1
    n = np.bincount(idx, minlength=len(bins))[:len(bins) - 1]
    s = np.bincount(idx, weights=sub[ok], minlength=len(bins))[:len(bins) - 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        return 0.5 * (bins[:-1] + bins[1:]), s / n


def _radial_start(e, centre, r_lo, r_hi, window, shown=None):
    """The radius in ``[r_lo, r_hi]`` where the azimuthal mean log energy drops most
    from the ``window`` px inside to the ``window`` px outside, and that drop."""
    r, prof = _radial_profile(e, centre, max(r_lo - window, 1.0), r_hi + window, 0.5, shown)
    k = int(round(window / 0.5))
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


def _energy_step_fit(e, centre, radius, band, shown=None):
    """Circle of the smooth step of the log energy over the annulus ``radius ± band``:
    ``a + b Φ((r - R)/w)`` by least squares (soft L1), returning centre, radius and the
    inside-minus-outside drop ``-b``."""
    from scipy.optimize import least_squares
    from scipy.special import erf

    H, W = e.shape
    r0 = max(int(centre[0] - radius - band - 2), 0), min(int(centre[0] + radius + band + 3), H)
    c0 = max(int(centre[1] - radius - band - 2), 0), min(int(centre[1] + radius + band + 3), W)
    rows, cols = np.mgrid[r0[0]:r0[1], c0[0]:c0[1]]
    y, x = rows + 0.5, cols + 0.5
    r = np.hypot(y - centre[0], x - centre[1])
    m = np.abs(r - radius) < band
    if shown is not None:
        m &= shown[r0[0]:r0[1], c0[0]:c0[1]]
    y, x, s, rm = y[m], x[m], e[r0[0]:r0[1], c0[0]:c0[1]][m], r[m]
    if len(s) < 50:
        return centre, radius, 0.0
    a0 = float(np.median(s[rm < radius]))
    b0 = float(np.median(s[rm >= radius])) - a0

    def resid(p):
        cy, cx, R, a, b, w = p
        rr = np.hypot(y - cy, x - cx)
        return a + b * 0.5 * (1.0 + erf((rr - R) / (math.sqrt(2.0) * abs(w) + 1e-3))) - s

    sol = least_squares(resid, [centre[0], centre[1], radius, a0, b0, 1.0], loss="soft_l1",
                        f_scale=float(np.std(s)) + 1e-12, max_nfev=200)
    cy, cx, R, a, b, _ = sol.x
    return (float(cy), float(cx)), float(R), float(-b)


def fit_limb(lum: np.ndarray, centre: tuple[float, float], pts: np.ndarray,
             nrm: np.ndarray, scale_range: tuple[float, float], *,
             shown: np.ndarray | None = None, iterations: int = 6) -> LimbFit | None:
    """Find a circular limb (see the module docstring) about ``centre`` (row, col; good
    to a few px), its size within ``scale_range`` times the outline ``pts`` (N, 2
    offsets from the axis, px, with outward normals ``nrm``). None where no drop of
    the fine-detail energy of at least :data:`MIN_ENERGY_STEP` is found."""
    radius0 = float(np.sqrt(np.mean(np.sum(pts ** 2, axis=1))))
    e, _ = energy_map(lum)
    e_shown = None if shown is None else (shown[1:, 1:] & shown[:-1, 1:] & shown[1:, :-1]
                                          & shown[:-1, :-1])
    band = max(LIMB_ANNULUS_PX, 0.06 * radius0 * scale_range[0])
    start, drop = _radial_start(e, centre, radius0 * scale_range[0],
                                radius0 * scale_range[1], band, e_shown)
    if not math.isfinite(start) or drop < MIN_ENERGY_STEP:
        return None
    c, R = centre, start
    for _ in range(2):
        c, R, step = _energy_step_fit(e, c, R, band, e_shown)
    if step < MIN_ENERGY_STEP:
        return None
    energy_c, energy_R = c, R
    lum_s = smooth(lum, LIMB_SMOOTHING_PX)
    A = np.column_stack([nrm[:, 0], nrm[:, 1], np.sum(pts * nrm, axis=1)])
    scale = R / radius0
    centre = c
    off = np.full(len(pts), np.nan)
    wts = np.zeros(0)
    good = np.zeros(len(pts), bool)
    res = np.zeros(0)
    for _ in range(iterations):
        off, _strength, _width = edge_offsets(lum_s, centre, scale, pts, nrm,
                                              LIMB_HALF_WIDTH_PX)
        good = np.isfinite(off)
        if shown is not None:
            at = np.rint(np.asarray(centre)[None, :] + scale * pts).astype(int)
            H, W = shown.shape
            ins = (at[:, 0] >= 0) & (at[:, 0] < H) & (at[:, 1] >= 0) & (at[:, 1] < W)
            good &= ins
            good[ins] &= shown[at[ins, 0], at[ins, 1]]
        if good.sum() < 8:
            return None
        x, wts = tukey_lstsq(A[good], off[good], np.ones(int(good.sum())))
        res = off[good] - A[good] @ x
        centre = (centre[0] + float(x[0]), centre[1] + float(x[1]))
        scale += float(x[2])
        if max(abs(x[0]), abs(x[1]), abs(x[2]) * radius0) < 1e-3:
            break
    inl = wts > 0
    rms = float(np.sqrt(np.mean(res[inl] ** 2))) if inl.any() else math.inf
    edges = np.asarray(centre)[None, :] + scale * pts + np.nan_to_num(off)[:, None] * nrm
    used = np.zeros(len(pts), bool)
    used[np.flatnonzero(good)[inl]] = True
    return LimbFit(center_px=(float(centre[0]), float(centre[1])),
                   radius_px=float(scale * radius0), energy_step=float(step),
                   energy_center_px=energy_c, energy_radius_px=energy_R,
                   points_used=int(used.sum()), points_total=len(pts),
                   residual_rms_px=rms, edge_points_px=edges[used],
                   used_index=np.flatnonzero(used), residuals_px=res[inl])
