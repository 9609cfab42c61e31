"""IPSF metrics (paper Sec. 3.2): cross-sections, kurtosis, depth variance V and V_avg.

Pure NumPy/SciPy on kernels laid out as in :mod:`mitsweep.io.bank` (rows down the image
(−v), columns right (+u)).

Definitions
-----------
- **Cross-section** along a unit image direction ``e``: the kernel sampled (bilinear)
  at pixel steps on the line through its intensity centroid along ``e``. For a point at
  polar angle θ, *radial* is ``e = (cos θ, sin θ)`` and *tangential* is ``e`` rotated by
  +90°.
- **Kurtosis** of a cross-section ``c(x)``: the intensity-weighted fourth standardised
  moment ``β₂ = m₄ / m₂²`` with ``m_k = Σ c(x) (x − μ)^k / Σ c(x)`` (the cross-section
  read as a distribution over position): 3 for a Gaussian, 1.8 for a uniform segment,
  large for a sharp peak on wide tails. (``scipy.stats.kurtosis(values)`` is the excess
  kurtosis of the *values* and is a different quantity.)
- **V** (paper Eq. 2, Kuthirummal et al.):

  .. math:: V(p_1, p_2) = \\sum_{u,v} \\Big( \\frac{|P_1 − P_2|^2}{|P_1|^2 + ε}
            + \\frac{|P_1 − P_2|^2}{|P_2|^2 + ε} \\Big) |W(u, v)|^2

  with ``P`` the K×K DFTs of the unit-sum kernels, ``W = 1/|f|`` (``|f|`` the radial
  frequency in cycles per pixel; ``W(0) = 0``, where unit-sum kernels agree anyway)
  and ``ε =`` :data:`EPSILON`.
- **V_avg** (Eq. 3): the mean over depths ``j`` (the first is the reference, so its
  term is 0 but still counted, as in the paper) and field points ``k`` of
  ``V(p_{j,k}, p_{1,k})``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import fft, ndimage

__all__ = ["EPSILON", "cross_section", "cross_sections", "kurtosis", "depth_variance",
           "v_avg", "centroid"]

#: ε of Eq. 2: the squared DFT magnitude below which a kernel is treated as having lost
#: the frequency (1e-3: ~ −30 dB of the DC term of a unit-sum kernel).
EPSILON = 1e-3


def centroid(kernel: ArrayLike) -> tuple[float, float]:
    """(row, col) intensity centroid of a (K, K) kernel, pixels.

    Parameters
    ----------
    kernel : (K, K) array_like
        A kernel with a positive sum.

    Returns
    -------
    (float, float)
        Row and column of the centroid, px from the first pixel's centre.
    """
    k = np.asarray(kernel, dtype=np.float64)
    s = k.sum()
    if not s > 0:
        raise ValueError("kernel: must have a positive sum")
    r, c = np.indices(k.shape)
    return float((k * r).sum() / s), float((k * c).sum() / s)


def cross_section(kernel: ArrayLike, direction: Iterable[float], *,
                  through: tuple[float, float] | None = None, half_length: int | None = None
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Kernel values along a line, at pixel steps (bilinear interpolation).

    Parameters
    ----------
    kernel : (K, K) array_like
    direction : (2,) array_like
        Unit direction in upright image coordinates (u right, v up).
    through : (row, col), optional
        Point the line passes through (default: the intensity centroid).
    half_length : int, optional
        Samples on each side (default K // 2).

    Returns
    -------
    x : (2 n + 1,) ndarray
        Position along the line, pixels.
    values : (2 n + 1,) ndarray
    """
    k = np.asarray(kernel, dtype=np.float64)
    K = k.shape[0]
    du, dv = (float(x) for x in direction)
    norm = math.hypot(du, dv)
    if not norm > 0:
        raise ValueError("direction: must be a non-zero 2-vector")
    du, dv = du / norm, dv / norm
    r0, c0 = centroid(k) if through is None else through
    n = K // 2 if half_length is None else int(half_length)
    x = np.arange(-n, n + 1, dtype=np.float64)
    rows, cols = r0 - dv * x, c0 + du * x
    vals = ndimage.map_coordinates(k, [rows, cols], order=1, mode="constant", cval=0.0)
    return x, vals


def cross_sections(kernel: ArrayLike, angle: float = 0.0, **kw: Any
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Radial and tangential cross-sections of an IPSF at polar angle ``angle`` (rad).

    Returns ``(x, radial, tangential)``; see :func:`cross_section`.

    Parameters
    ----------
    kernel : (K, K) array_like
        The IPSF.
    angle : float, optional
        Polar angle of the image radius, rad, counter-clockwise from +u (default 0).
    **kw
        ``through``, ``half_length``: as :func:`cross_section`.
    """
    e_r = (math.cos(angle), math.sin(angle))
    e_t = (-math.sin(angle), math.cos(angle))
    x, rad = cross_section(kernel, e_r, **kw)
    _, tan = cross_section(kernel, e_t, **kw)
    return x, rad, tan


def kurtosis(values: ArrayLike, x: ArrayLike | None = None) -> float:
    """Intensity-weighted fourth standardised moment of a profile (Gaussian = 3).

    Parameters
    ----------
    values : (n,) array_like
        Non-negative profile (a cross-section).
    x : (n,) array_like, optional
        Positions (default 0, 1, ...; the result is scale- and shift-invariant).
    """
    c = np.asarray(values, dtype=np.float64)
    if c.ndim != 1 or c.size < 3:
        raise ValueError(f"values: need a 1-D profile of >= 3 samples, got shape {c.shape}")
    if np.any(c < 0) or not c.sum() > 0:
        raise ValueError("values: a profile must be non-negative with a positive sum")
    x = np.arange(c.size, dtype=np.float64) if x is None else np.asarray(x, dtype=np.float64)
    w = c / c.sum()
    mu = (w * x).sum()
    m2 = (w * (x - mu) ** 2).sum()
    if not m2 > 0:
        raise ValueError("values: a single-sample spike has no kurtosis (zero variance)")
    m4 = (w * (x - mu) ** 4).sum()
    return float(m4 / (m2 * m2))


def _weight2(K: int) -> np.ndarray:
    f = fft.fftfreq(K)
    fr = np.hypot(f[:, None], f[None, :])
    with np.errstate(divide="ignore"):
        w2 = np.where(fr > 0, 1.0 / (fr * fr), 0.0)
    return w2


def depth_variance(p1: ArrayLike, p2: ArrayLike, *, epsilon: float = EPSILON) -> float:
    """V(p1, p2) of paper Eq. 2 (see the module docstring for W and ε).

    Parameters
    ----------
    p1, p2 : (K, K) array_like
        Kernels on the same grid; normalised to unit sum here.
    """
    a = np.asarray(p1, dtype=np.float64)
    b = np.asarray(p2, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 2 or a.shape[0] != a.shape[1]:
        raise ValueError(f"kernels: need two (K, K) arrays of the same shape, got "
                         f"{a.shape} and {b.shape}")
    if not (a.sum() > 0 and b.sum() > 0):
        raise ValueError("kernels: must have positive sums")
    if not epsilon > 0:
        raise ValueError(f"epsilon: must be > 0, got {epsilon!r}")
    P1, P2 = fft.fft2(a / a.sum()), fft.fft2(b / b.sum())
    d2 = np.abs(P1 - P2) ** 2
    terms = d2 / (np.abs(P1) ** 2 + epsilon) + d2 / (np.abs(P2) ** 2 + epsilon)
    return float((terms * _weight2(a.shape[0])).sum())


def v_avg(kernels: ArrayLike, *, epsilon: float = EPSILON) -> float:
    """V_avg of paper Eq. 3.

    Parameters
    ----------
    kernels : (n_depths, n_points, K, K) array_like
        IPSFs; depth index 0 is the reference ``p_{1,k}``.
    """
    k = np.asarray(kernels)
    if k.ndim != 4:
        raise ValueError(f"kernels: need (n_depths, n_points, K, K), got shape {k.shape}")
    total = 0.0
    for j in range(k.shape[0]):
        for i in range(k.shape[1]):
            total += depth_variance(k[j, i], k[0, i], epsilon=epsilon)
    return total / (k.shape[0] * k.shape[1])
