"""The robust least squares of the rim fit: Tukey's biweight by iteratively reweighted
least squares, and the standard error of what it fits."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["tukey_lstsq", "consensus_lstsq", "centre_standard_error", "TUKEY_C",
           "EDGE_CORRELATION_PX", "CONSENSUS_HYPOTHESES"]

#: Tukey's biweight constant (95% efficiency at Gaussian residuals), in units of the
#: residuals' robust scale (1.4826 MAD).
TUKEY_C = 4.685
#: Outline length (px) over which neighbouring edge points count as one independent
#: measurement (the profiles overlap in the smoothing and the rim's blur).
EDGE_CORRELATION_PX = 2.0
#: Hypotheses drawn by :func:`consensus_lstsq`: with a third of the rows' true value
#: among their candidates, a draw of 3 rows is right with probability 1/27, and 2048
#: draws all miss with probability ~1e-33.
CONSENSUS_HYPOTHESES = 2048


def tukey_lstsq(A: np.ndarray, b: np.ndarray, sigma: np.ndarray, *,
                iterations: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Solve ``A x ≈ b`` robustly: each row ``i`` weighted by ``1/sigma[i]`` (its
    uncertainty) and by Tukey's biweight of its standardised residual, the scale being
    the median absolute deviation of those residuals, for ``iterations`` rounds.

    Parameters
    ----------
    A : (M, P) ndarray
    b : (M,) ndarray
    sigma : (M,) ndarray
        Each row's uncertainty (relative values suffice).
    iterations : int

    Returns
    -------
    x : (P,) ndarray
    weights : (M,) ndarray
        The biweights of the last round: 0 for the outliers, in (0, 1] for the inliers.
    """
    weights = np.ones(len(b))
    x = np.zeros(A.shape[1])
    for _ in range(iterations):
        sw = np.sqrt(weights) / sigma
        x, *_ = np.linalg.lstsq(A * sw[:, None], b * sw, rcond=None)
        z = (b - A @ x) / sigma
        s = 1.4826 * np.median(np.abs(z - np.median(z))) + 1e-6
        u = z / (TUKEY_C * s)
        weights = np.where(np.abs(u) < 1, (1 - u * u) ** 2, 0.0)
    return x, weights


def centre_standard_error(A: np.ndarray, residuals: np.ndarray, length_px: float) -> float:
    """Standard error (px) of the fitted centre (the larger of row and column): the
    least-squares covariance ``s² (AᵀA)⁻¹`` of the inliers' design ``A`` (M, 3) and
    residuals, with the points counted as ``length_px / EDGE_CORRELATION_PX``
    independent measurements, not M.

    Parameters
    ----------
    A : (M, 3) ndarray
        The inliers' design matrix of the linear circle fit.
    residuals : (M,) ndarray
        Their residuals, px.
    length_px : float
        Length of outline the inliers cover, px.
    """
    m = len(residuals)
    if m <= A.shape[1]:
        return math.inf
    s2 = float(np.sum(residuals ** 2)) / (m - A.shape[1])
    independent = max(A.shape[1] + 1.0, min(m, length_px / EDGE_CORRELATION_PX))
    cov = s2 * np.linalg.pinv(A.T @ A) * (m / independent)
    return float(math.sqrt(max(cov[0, 0], cov[1, 1])))


def consensus_lstsq(A: np.ndarray, candidates: np.ndarray, tolerance: float, *,
                    hypotheses: int = CONSENSUS_HYPOTHESES,
                    seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Solve ``A x ≈ b`` where each row's ``b`` is one of several candidates, unknown
    which: RANSAC (Fischler & Bolles 1981) over rows *and* candidates. Each hypothesis
    solves ``P`` rows drawn at random, each with one of its candidates at random; the
    hypothesis under which the most rows have a candidate within ``tolerance`` wins, and
    is refitted by least squares to those candidates.

    Where the strongest edge along a normal is often the wrong one (a dim stretch of rim
    beside a strong edge of the reflection), the rim is still the one outline that most
    normals show *an* edge on.

    Parameters
    ----------
    A : (M, P) ndarray
    candidates : (M, K) ndarray
        Each row's candidate values, NaN where a row has fewer than K.
    tolerance : float
        Largest residual of a row counted as agreeing.
    hypotheses : int
        Hypotheses drawn.
    seed : int
        Seed of the draws (the result is reproducible).

    Returns
    -------
    x : (P,) ndarray
        NaN where no hypothesis could be solved.
    chosen : (M,) ndarray
        Each agreeing row's candidate under ``x``, NaN for the others.
    """
    M, P = A.shape
    finite = np.isfinite(candidates)
    count = finite.sum(axis=1)
    rows = np.flatnonzero(count > 0)
    none = (np.full(P, np.nan), np.full(M, np.nan))
    if len(rows) < P:
        return none
    # candidates sorted so that each row's finite ones come first
    order = np.argsort(~finite, axis=1, kind="stable")
    cand = np.take_along_axis(candidates, order, axis=1)
    rng = np.random.default_rng(seed)
    pick = rng.choice(rows, size=(hypotheses, P))
    which = (rng.random((hypotheses, P)) * count[pick]).astype(int)
    Ah = A[pick]
    bh = cand[pick, which]
    det = np.linalg.det(Ah)
    scale = np.prod(np.linalg.norm(Ah, axis=2), axis=1) + 1e-300
    ok = np.abs(det) > 1e-6 * scale  # rows neither repeated nor nearly parallel
    if not ok.any():
        return none
    xs = np.linalg.solve(Ah[ok], bh[ok][..., None])[..., 0]
    best, best_n = None, -1
    for chunk in range(0, len(xs), 256):
        pred = xs[chunk:chunk + 256] @ A.T
        # a row agrees where any of its candidates is within the tolerance (a missing
        # candidate, NaN, never is)
        agree = (np.abs(cand[None, :, :] - pred[:, :, None]) <= tolerance).any(axis=2)
        n = agree.sum(axis=1)
        i = int(np.argmax(n))
        if n[i] > best_n:
            best, best_n = xs[chunk + i], int(n[i])
    assert best is not None
    x = best
    chosen = np.full(M, np.nan)
    for _ in range(2):  # refit to the agreeing candidates, then take them again
        err = np.abs(cand - (A @ x)[:, None])
        err = np.where(np.isfinite(err), err, np.inf)
        k = np.argmin(err, axis=1)
        near = np.take_along_axis(cand, k[:, None], axis=1)[:, 0]
        agree = np.take_along_axis(err, k[:, None], axis=1)[:, 0] <= tolerance
        if agree.sum() < P:
            break
        x, *_ = np.linalg.lstsq(A[agree], near[agree], rcond=None)
        chosen = np.where(agree, near, np.nan)
    return x, chosen
