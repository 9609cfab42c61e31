"""Step 1 of the rim search: where the outline is, to a reduced pixel and a scale step.

The gradient's double-angle orientation field (sign-free: a rim may be brighter or darker
than what surrounds it), of the luminance and of the local energy of fine detail (a
reflection about as bright as what surrounds the mirror still differs from it in detail:
the sweep focuses on the reflection, not on the surroundings), correlated by FFT with the
outline's normals for each scale searched, on a copy reduced so that the outline's radius
is :data:`COARSE_RADIUS_PX`-64 px. The score is the mean alignment times the square root
of the outline's length (a mean over ~perimeter samples), so that a small outline on busy
texture does not outscore the rim. At the best position, of the scale peaks within half
the best score, the one nearest the predicted size is kept: a holder around the mirror is
a concentric outline too, and the rim is the one the setup predicts. Where the setup is
only roughly right, that rule can pick the holder: the score volume's other local maxima
are offered too (:func:`coarse_candidates`), and the refinement decides between them.
"""

from __future__ import annotations

import math

import numpy as np

from .image import reduce_by, smooth, texture_energy

__all__ = ["coarse_search", "coarse_candidates", "score_volume", "search_scales",
           "MAX_CANDIDATES", "CANDIDATE_SEPARATION", "COARSE_RADIUS_PX", "COARSE_SCALE_STEP",
           "DETAIL_REDUCTION"]

#: Radius (px) of the outline in the reduced copy used for the coarse search (at least).
COARSE_RADIUS_PX = 32.0
#: The fine-detail cue is computed on a copy reduced by ``factor // DETAIL_REDUCTION``
#: (the coarse search's reduction ``factor``): full resolution up to a 128 px outline.
DETAIL_REDUCTION = 4
#: Relative step of the scales searched coarsely (4%: ~1.3 px at 32 px).
COARSE_SCALE_STEP = 1.04
#: Starting points refined at most (:func:`coarse_candidates`).
MAX_CANDIDATES = 6
#: Reduced pixels (and one scale step) within which a maximum counts as one already
#: taken (:func:`coarse_candidates`): a flat top of the score around a centre between
#: reduced pixels is one outline, not four.
CANDIDATE_SEPARATION = 2


def search_scales(lo: float, hi: float) -> np.ndarray:
    """Outline sizes from ``lo`` to ``hi`` in geometric steps of at most
    :data:`COARSE_SCALE_STEP` (both ends included, at least two).

    Parameters
    ----------
    lo, hi : float
        Smallest and largest outline size, relative to the prediction (``0 < lo < hi``).
    """
    n = max(2, int(math.ceil(math.log(hi / lo) / math.log(COARSE_SCALE_STEP))) + 1)
    return np.geomspace(lo, hi, n)


def score_volume(lum: np.ndarray, pts: np.ndarray, nrm: np.ndarray,
                 scales: np.ndarray) -> tuple[np.ndarray, int]:
    """The coarse search's score for every reduced position and scale, and the reduction.

    Parameters
    ----------
    lum : (H, W) ndarray
        Linear luminance of the photo.
    pts : (N, 2) ndarray
        The predicted outline's points as ``(row, col)`` offsets from the axis, px.
    nrm : (N, 2) ndarray
        Their outward unit normals, ``(row, col)``.
    scales : (S,) ndarray
        The outline sizes tried, relative to ``pts`` (:func:`search_scales`).

    Returns
    -------
    volume : (S, h, w) ndarray
        Score of the outline centred on each pixel of the reduced copy, per scale.
    factor : int
        The reduction: reduced pixel ``(i, j)`` is centred on full-resolution
        ``((i + 0.5) factor - 0.5, (j + 0.5) factor - 0.5)``.
    """
    from scipy.fft import irfft2, next_fast_len, rfft2

    radius = float(np.sqrt(np.mean(np.sum(pts ** 2, axis=1))))
    factor = max(1, int(radius / COARSE_RADIUS_PX))
    j1 = j2 = 0.0
    # Two cues, each an orientation field of unit strength at most: the luminance, and
    # the local texture energy, where a rim of little contrast (a reflection as bright
    # as what surrounds the mirror, as on the rendered tilted paraboloid) still shows:
    # the reflection is detailed, what surrounds it far out of focus.
    # The detail is measured on a copy reduced by a quarter of the search's factor: the
    # same as at full resolution for outlines up to 128 px, and on a large photo (whose
    # finest detail is demosaicking and compression) the cost of one reduced pass.
    pre = max(1, factor // DETAIL_REDUCTION)
    factor = pre * (factor // pre)  # both cues on one grid
    fine = reduce_by(lum, pre)
    for cue, f in ((lum, factor), (texture_energy(fine), factor // pre)):
        small = smooth(reduce_by(cue, f), 1.0)
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
    volume = np.empty((len(scales), H, W))
    for q, k in enumerate(scales):
        p = pts * k / factor
        flat = (np.round(p[:, 0]).astype(int) % shape[0]) * shape[1] \
            + np.round(p[:, 1]).astype(int) % shape[1]
        t1 = np.bincount(flat, weights=c2, minlength=shape[0] * shape[1]).reshape(shape)
        t2 = np.bincount(flat, weights=s2, minlength=shape[0] * shape[1]).reshape(shape)
        score = irfft2(F1 * np.conj(rfft2(t1)) + F2 * np.conj(rfft2(t2)), shape)[:H, :W]
        # Mean alignment along the outline, times the square root of its length: the
        # significance of a mean over ~perimeter independent samples, so that a small
        # outline on busy texture does not outscore the rim.
        volume[q] = score * (math.sqrt(k) / len(p))
    return volume, factor


def coarse_candidates(lum: np.ndarray, pts: np.ndarray, nrm: np.ndarray,
                      scales: np.ndarray, *, max_candidates: int = MAX_CANDIDATES
                      ) -> list[tuple[tuple[float, float], float, float]]:
    """Starting points for the refinement: ``[(center (row, col), scale, score), ...]``
    in full-resolution pixels, the first :func:`coarse_search`'s.

    The others are the score volume's local maxima (over position and scale) scoring at
    least half the best, strongest first, more than :data:`CANDIDATE_SEPARATION` reduced
    pixels or a scale step from those already taken: a concentric outline of another
    size (a holder, the camera's own reflection), or the same size a few reduced pixels
    away, where a faint stretch of the rim and a strong edge inside it pulled the first
    (a real paraboloid's dim lower rim). The refinement decides between them
    (:func:`mitsweep.photo.rim.fit_edges`).

    Parameters
    ----------
    lum, pts, nrm, scales
        As :func:`score_volume`.
    max_candidates : int
        At most this many starting points.
    """
    from scipy.ndimage import maximum_filter

    volume, factor = score_volume(lum, pts, nrm, scales)
    S, H, W = volume.shape
    q, row, col = (int(v) for v in np.unravel_index(int(np.argmax(volume)), volume.shape))
    top = float(volume[q, row, col])
    # At that position: of the scale peaks within half the best, the nearest to k = 1.
    local = np.array([volume[j, max(0, row - 1):row + 2, max(0, col - 1):col + 2].max()
                      for j in range(S)])
    peaks = [j for j in range(S)
             if local[j] >= 0.5 * top and (j == 0 or local[j] >= local[j - 1])
             and (j == S - 1 or local[j] >= local[j + 1])]
    j = min(peaks, key=lambda p: abs(math.log(scales[p]))) if peaks else \
        int(np.argmax(local))
    win = volume[j, max(0, row - 2):row + 3, max(0, col - 2):col + 3]
    dr, dc = np.unravel_index(int(np.argmax(win)), win.shape)
    row, col = max(0, row - 2) + int(dr), max(0, col - 2) + int(dc)

    def full(r: int, c: int) -> tuple[float, float]:
        return ((r + 0.5) * factor - 0.5, (c + 0.5) * factor - 0.5)

    out = [(full(row, col), float(scales[j]), float(local[j]))]
    if max_candidates <= 1:   # coarse_search's: no need of the volume's other maxima
        return out
    taken = [(j, row, col)]
    # (a featureless photo scores nothing anywhere: its maxima are no outlines)
    is_max = (volume == maximum_filter(volume, size=(3, 3, 3), mode="nearest")) \
        & (volume >= 0.5 * top) & (volume > 0.0)
    found = np.argwhere(is_max)
    order = np.argsort(-volume[tuple(found.T)], kind="stable")
    for qq, r, c in found[order]:
        if len(out) >= max_candidates:
            break
        if any(abs(qq - a) <= 1 and max(abs(r - b), abs(c - d)) <= CANDIDATE_SEPARATION
               for a, b, d in taken):
            continue
        taken.append((int(qq), int(r), int(c)))
        out.append((full(int(r), int(c)), float(scales[qq]), float(volume[qq, r, c])))
    return out


def coarse_search(lum: np.ndarray, pts: np.ndarray, nrm: np.ndarray,
                  scales: np.ndarray) -> tuple[tuple[float, float], float, float]:
    """Best ``(center (row, col), scale, score)`` of the outline in full-resolution
    pixels: the best position; at it, of the scale peaks within half the best score, the
    nearest to the prediction (see the module docstring).

    Parameters
    ----------
    lum, pts, nrm, scales
        As :func:`score_volume`.
    """
    return coarse_candidates(lum, pts, nrm, scales, max_candidates=1)[0]
