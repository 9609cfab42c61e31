"""The robust least squares of the rim fit: Tukey's biweight by iteratively reweighted
least squares, and the standard error of what it fits."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["tukey_lstsq", "centre_standard_error", "TUKEY_C", "EDGE_CORRELATION_PX"]

#: Tukey's biweight constant (95% efficiency at Gaussian residuals), in units of the
#: residuals' robust scale (1.4826 MAD).
TUKEY_C = 4.685
#: Outline length (px) over which neighbouring edge points count as one independent
#: measurement (the profiles overlap in the smoothing and the rim's blur).
EDGE_CORRELATION_PX = 2.0


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
