"""Step 2 of the rim search: sub-pixel edge positions along the outline's normals, and
how much the outline stands out from its surroundings.

Along the normal at each outline point, the intensity profile's derivative (one sign, the
dominant one) gives the edge as the peak of its lobe (a Gaussian fitted to its top,
:func:`gaussian_peak`), which is the mean chief-ray position of a defocused, breathing
edge (a symmetric blur about each chief-ray image), so the fit lands on the mid-travel
outline. The peak, not the lobe's centroid: where content of the reflection meets the rim
(a bright banner whose far edge has the other sign) the lobe's flanks are not the blur's,
and on Mitsuba renders of the tilted paraboloid its centroid moved the axis by
0.21-0.35 px, its peak by 0.05-0.18 px.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["edge_offsets", "edge_candidates", "gaussian_peak", "edge_prominence",
           "blurred_step_offsets", "EDGE_PEAK_HALF_WIDTH_PX", "PROMINENCE_TRIM",
           "STEP_MODEL_HALF_PX", "STEP_MODEL_SIGMAS_PX"]

#: Half-width (px) of the top of the derivative lobe fitted by a Gaussian to locate the
#: edge (:func:`gaussian_peak`). Measured on Mitsuba sweep renders of the tilted
#: paraboloid (200-300 px, 64-128 spp, 8 renders): the lobe's centroid leaves the axis
#: 0.20-0.33 px off, a Gaussian over the lobe above half its peak 0.18-0.27, above 0.7
#: of it 0.13-0.23, over +-0.25 px 0.06-0.20, over +-0.5 px 0.05-0.18.
EDGE_PEAK_HALF_WIDTH_PX = 0.5
#: Half-length (px) of the profile a blurred step is fitted to (:func:`blurred_step_offsets`):
#: a few blur widths of the sharp limbs it is used on (0.5-0.7 px chosen on the renders).
STEP_MODEL_HALF_PX = 3.0
#: Blur widths (Gaussian standard deviation, px) tried by :func:`blurred_step_offsets`;
#: the one with the least residual over all the normals is kept.
STEP_MODEL_SIGMAS_PX = (0.5, 0.7, 0.9, 1.2, 1.6, 2.1, 2.8)
#: Share of the outline's points cut at each end of the mean absolute derivative of
#: :func:`edge_prominence`.
PROMINENCE_TRIM = 0.2


def _profiles(lum_s: np.ndarray, centre: tuple[float, float], scale: float,
              pts: np.ndarray, nrm: np.ndarray, half: float,
              step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The luminance along each normal, ``step`` px apart within ``half`` px of the
    outline (bilinear): the positions ``t``, the (N, T) profiles, and which profiles lie
    wholly inside the photo."""
    from scipy.ndimage import map_coordinates

    t = np.arange(-half, half + step / 2, step)
    base = np.asarray(centre)[None, :] + scale * pts
    coords = base[:, None, :] + t[None, :, None] * nrm[:, None, :]
    H, W = lum_s.shape
    inside = np.all((coords[..., 0] >= 0) & (coords[..., 0] <= H - 1)
                    & (coords[..., 1] >= 0) & (coords[..., 1] <= W - 1), axis=1)
    prof = map_coordinates(lum_s, [coords[..., 0].ravel(), coords[..., 1].ravel()],
                           order=1, mode="nearest").reshape(coords.shape[:2])
    return t, prof, inside


def edge_offsets(lum_s: np.ndarray, centre: tuple[float, float], scale: float,
                 pts: np.ndarray, nrm: np.ndarray, half: float, *,
                 outermost: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sub-pixel edge offset along each normal (NaN where no edge), its contrast (the
    integrated derivative) and its width (the derivative lobe's RMS width, px).

    The edge is the top of the lobe of the dominant-sign derivative around its highest
    peak (:func:`gaussian_peak`; the lobe's centroid where its top cannot be fitted), or,
    with ``outermost``, around the outermost peak at least half as high: the rim is
    the outer boundary of the mirror's content, whose own edges (sharp: the reflection
    is what the sweep focuses on) lie inside it, while what surrounds the mirror is
    usually far out of focus.

    Parameters
    ----------
    lum_s : (H, W) ndarray
        Smoothed luminance.
    centre : (float, float)
        The outline's centre ``(row, col)``, px.
    scale : float
        The outline's size relative to ``pts``.
    pts, nrm : (N, 2) ndarray
        Outline points (offsets from the centre, px) and outward unit normals.
    half : float
        Half-length of the profile sampled along each normal, px.
    outermost : bool
        Take the outermost strong peak instead of the highest (see above).
    """
    step = 0.25
    t, prof, inside = _profiles(lum_s, centre, scale, pts, nrm, half, step)
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
    # :func:`gaussian_peak`); the lobe's centroid is the fallback where the top is too
    # narrow to fit.
    peak_at = gaussian_peak(ds, t, at[:, 0], above & (k > left) & (k < right))
    off = np.where(np.isfinite(peak_at), peak_at, off)
    step_size = total * step  # the integrated derivative: the edge's contrast
    off = np.where(inside & (total > 0), off, np.nan)
    # The lobe's RMS width about its centroid: how wide the edge is (blur, defocus,
    # demosaicking, a limb's soft fall-off), which bounds how well it can be placed.
    with np.errstate(invalid="ignore", divide="ignore"):
        centroid = (wgt * t[None, :]).sum(axis=1) / total
        width = np.sqrt((wgt * (t[None, :] - centroid[:, None]) ** 2).sum(axis=1) / total)
    return off, step_size, np.where(np.isfinite(off), width, np.nan)


def blurred_step_offsets(lum: np.ndarray, centre: tuple[float, float], scale: float,
                         pts: np.ndarray, nrm: np.ndarray, reach: float = 1.5,
                         ) -> tuple[np.ndarray, np.ndarray, float]:
    """Sub-pixel edge offset along each normal from a model of the whole profile: a step
    blurred by a Gaussian, on a ramp, ``a + b Φ((t - t0) / σ) + c t``, fitted (least
    squares) to the luminance (not smoothed) within :data:`STEP_MODEL_HALF_PX` of the outline, ``t0``
    searched within ``reach`` px of it (to 1/20 px, then the vertex of a parabola through
    the residuals), ``σ`` one of :data:`STEP_MODEL_SIGMAS_PX` shared by all normals.

    Used for the sphere's limb (:mod:`mitsweep.photo.limb`), whose steps it places
    better than the peak of a smoothed profile's derivative on the sweep renders (figures
    there). On drawn discs, a ramp or a texture on one side of the step pulls both alike
    (``tests/test_photo_step_model.py``): it is a measured gain on the limb, not a cure
    for detail beside an edge. A step beyond the reach is not reported as such: the
    offset is wherever the model fits best within it (NaN only at its ends), so the
    circle it starts from should be within a pixel of the step.

    Parameters
    ----------
    lum : (H, W) ndarray
        Luminance, not smoothed (the model has its own blur).
    centre, scale, pts, nrm
        As :func:`edge_offsets`.
    reach : float
        How far from the outline (px) the step is looked for.

    Returns
    -------
    offsets : (N,) ndarray
        The step's position along each normal, px (NaN where it is at the end of the
        reach or the profile leaves the photo).
    steps : (N,) ndarray
        Each step's height ``b`` (its sign: brighter outside where positive).
    sigma : float
        The blur kept, px.
    """
    from scipy.special import ndtr

    step = 0.25
    t, prof, inside = _profiles(lum, centre, scale, pts, nrm, STEP_MODEL_HALF_PX, step)
    n = len(pts)
    t0s = np.arange(-reach, reach + 1e-9, 0.05)
    energy = np.sum(prof ** 2, axis=1)
    best = (math.inf, STEP_MODEL_SIGMAS_PX[0], np.zeros((len(t0s), n)))
    for sigma in STEP_MODEL_SIGMAS_PX:
        rss = np.empty((len(t0s), n))
        for i, t0 in enumerate(t0s):
            # the residual of a least-squares fit: what an orthonormal basis of the
            # model's columns leaves of each profile
            q, _ = np.linalg.qr(np.column_stack([np.ones_like(t), ndtr((t - t0) / sigma), t]))
            rss[i] = energy - np.sum((prof @ q) ** 2, axis=1)
        total = float(np.sum(rss.min(axis=0)[inside]))
        if total < best[0]:
            best = (total, sigma, rss)
    _, sigma, rss = best
    k = np.argmin(rss, axis=0)
    kk = np.clip(k, 1, len(t0s) - 2)
    ix = np.arange(n)
    y0, y1, y2 = rss[kk - 1, ix], rss[kk, ix], rss[kk + 1, ix]
    curv = y0 - 2.0 * y1 + y2
    with np.errstate(divide="ignore", invalid="ignore"):
        shift = np.where(curv > 0, 0.5 * (y0 - y2) / curv, 0.0)
    off = t0s[kk] + 0.05 * np.clip(shift, -1.0, 1.0)
    off[(k == 0) | (k == len(t0s) - 1) | ~inside] = np.nan
    # each profile's step height at its offset
    u = (t[None, :] - np.nan_to_num(off)[:, None]) / sigma
    A = np.stack([np.ones_like(u), ndtr(u), np.broadcast_to(t, u.shape)], axis=-1)
    coef = np.linalg.solve(np.einsum("ntj,ntk->njk", A, A),
                           np.einsum("ntj,nt->nj", A, prof)[..., None])[..., 0]
    return off, coef[:, 1], float(sigma)


def edge_candidates(lum_s: np.ndarray, centre: tuple[float, float], scale: float,
                    pts: np.ndarray, nrm: np.ndarray, half: float, floor: float,
                    k: int = 4) -> np.ndarray:
    """(N, k) offsets along each normal of its ``k`` strongest edges of either sign
    (local maxima of the absolute derivative, to a quarter pixel; NaN where fewer stand
    above ``floor``), for :func:`mitsweep.photo.robust.consensus_lstsq`.

    Parameters
    ----------
    lum_s, centre, scale, pts, nrm, half
        As :func:`edge_offsets`.
    floor : float
        Smallest derivative (per px) of an edge counted.
    k : int
        Candidates per normal at most.
    """
    step = 0.25
    t, prof, inside = _profiles(lum_s, centre, scale, pts, nrm, half, step)
    d = np.abs(np.gradient(prof, step, axis=1))
    peak = np.zeros_like(d, dtype=bool)
    peak[:, 1:-1] = (d[:, 1:-1] >= d[:, :-2]) & (d[:, 1:-1] > d[:, 2:]) \
        & (d[:, 1:-1] > floor)
    strength = np.where(peak, d, -np.inf)
    top = np.argsort(-strength, axis=1)[:, :k]
    out = np.where(np.take_along_axis(peak, top, axis=1), t[top], np.nan)
    out[~inside] = np.nan
    return out


def gaussian_peak(ds: np.ndarray, t: np.ndarray, at: np.ndarray,
                   lobe: np.ndarray) -> np.ndarray:
    """(N,) position along ``t`` of each profile's derivative peak: the vertex of the
    parabola fitted (least squares) to ``log ds`` over the samples of the ``lobe``
    within :data:`EDGE_PEAK_HALF_WIDTH_PX` of its peak sample ``at``, i.e. a Gaussian
    through the top of the lobe, kept within those samples (a flat or one-sided top
    leaves the peak sample); NaN where the lobe has fewer than 3 samples there.

    The top of a blurred step's derivative is where the step is, whatever the step's
    size (a symmetric blur); its flanks are where content next to the rim (a reflection's
    bright banner ending at the rim, whose far edge has the opposite sign) adds to or
    takes from the lobe, which moves a centroid over the whole lobe but not its top.

    Parameters
    ----------
    ds : (N, T) ndarray
        Derivative profiles (positive: the dominant sign), one per outline point.
    t : (T,) ndarray
        Their sample positions along the normal, px (evenly spaced).
    at : (N,) int ndarray
        Index of each profile's peak sample.
    lobe : (N, T) bool ndarray
        The samples of each profile's lobe around its peak.
    """
    n = len(ds)
    pk = ds[np.arange(n), at]
    # Only the samples within the half-width of the peak take part: gather that window
    # (the whole profile is hundreds of samples on a large photo's rim).
    step = float(t[1] - t[0]) if len(t) > 1 else 1.0
    m = int(math.ceil(EDGE_PEAK_HALF_WIDTH_PX / step + 1e-9))
    cols = np.clip(at[:, None] + np.arange(-m, m + 1)[None, :], 0, ds.shape[1] - 1)
    inside = (at[:, None] + np.arange(-m, m + 1)[None, :] == cols)
    ds, lobe, tt = np.take_along_axis(ds, cols, 1), np.take_along_axis(lobe, cols, 1), t[cols]
    x = tt - t[at][:, None]  # about the peak sample: well conditioned
    use = inside & lobe & (np.abs(x) <= EDGE_PEAK_HALF_WIDTH_PX + 1e-9) & (ds > 0)
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


def edge_prominence(lum_s: np.ndarray, centre: tuple[float, float], scale: float,
                    pts: np.ndarray, nrm: np.ndarray, half: float, radius: float) -> float:
    """How much stronger the image's gradient is on the fitted outline than beside it:
    the absolute derivative across the outline, averaged over the outline's points, within
    ``half``/2 of it, over its median from 2 ``half`` to 4 ``half`` on both sides (a
    rim: several; texture: about 1).

    The average over points is a trimmed mean (:data:`PROMINENCE_TRIM` cut at each
    end): a strong edge beside part of the outline only (the black border of a render
    cropped to the mirror's window 8 px outside the rim, a holder's arm, a bright
    object in the reflection) would otherwise raise the "beside" level of the whole
    outline. On Mitsuba sweep renders of the paraboloid, cropped to the mirror's
    window, it raises the prominence from 3.8-5.0 to 5.9-10.4; on a photo without a
    mirror it stays below 2.

    Parameters
    ----------
    lum_s : (H, W) ndarray
        Smoothed luminance.
    centre : (float, float)
        The fitted outline's centre ``(row, col)``, px.
    scale : float
        Its size relative to ``pts``.
    pts, nrm : (N, 2) ndarray
        Outline points (offsets from the centre, px) and outward unit normals.
    half : float
        Half-width of the edge search, px: "on" is within ``half``/2 of the outline.
    radius : float
        The outline's radius, px (the profiles reach at most half of it).
    """
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
