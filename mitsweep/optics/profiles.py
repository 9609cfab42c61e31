"""Mirror profiles: conic and even-asphere sag, slope, curvature, principal radii.

The mirror surface in its local frame is ``z = -s(ρ)`` with ``ρ = sqrt(x² + y²)``: the
vertex at the origin, convex toward +z (the camera). With ``q = sqrt(R² - (1+k) ρ²)``
the conic sag is written in its cancellation-free form

.. math:: s(ρ) = \\frac{ρ^2}{R + q} + \\sum_i a_{2i} ρ^{2i},

and every quantity below is expressed through ``q`` so that nothing divides 0 by 0 on
the axis (ρ = 0) and nothing overflows at the rim of a hemisphere (q = 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..config import Mirror

__all__ = ["Profile", "conic_sag", "profile_of"]


def conic_sag(rho: ArrayLike, radius: float, conic: float) -> NDArray[np.float64]:
    """Sag of a conic of vertex radius ``radius`` and conic constant ``conic``, mm.

    Parameters
    ----------
    rho : array_like
        Radial coordinate, mm.
    radius, conic : float
        Vertex radius of curvature R (mm) and conic constant k.

    Returns
    -------
    ndarray
        ``ρ² / (R + sqrt(R² - (1+k) ρ²))``; NaN outside the conic's domain.
    """
    rho = np.asarray(rho, dtype=float)
    q = np.sqrt(radius * radius - (1.0 + conic) * rho * rho)
    return rho * rho / (radius + q)


@dataclass(frozen=True)
class Profile:
    """A convex rotationally symmetric mirror profile (conic plus even asphere).

    Parameters
    ----------
    radius : float
        Vertex radius of curvature R, mm.
    conic : float
        Conic constant k.
    aspheric : tuple of float
        Coefficients (a4, a6, ...) of ρ⁴, ρ⁶, ... in the sag.
    """

    radius: float
    conic: float = 0.0
    aspheric: tuple[float, ...] = ()

    def _q(self, rho):
        return np.sqrt(np.maximum(self.radius ** 2 - (1.0 + self.conic) * rho * rho, 0.0))

    def _poly(self, rho):
        """Asphere terms: sag, (slope/ρ) and second derivative."""
        sag = np.zeros_like(rho)
        g = np.zeros_like(rho)
        d2 = np.zeros_like(rho)
        r2 = rho * rho
        for j, a in enumerate(self.aspheric):
            n = 2 * (j + 2)  # 4, 6, ...
            sag = sag + a * r2 ** (n // 2)
            g = g + n * a * r2 ** (n // 2 - 1)
            d2 = d2 + n * (n - 1) * a * r2 ** (n // 2 - 1)
        return sag, g, d2

    def sag(self, rho: ArrayLike) -> NDArray[np.float64]:
        """s(ρ), mm (positive, away from the camera).

        Parameters
        ----------
        rho : array_like
            Radial coordinate ρ, mm, >= 0 (inside :meth:`max_rho`).
        """
        rho = np.asarray(rho, dtype=float)
        return rho * rho / (self.radius + self._q(rho)) + self._poly(rho)[0]

    def slope_over_rho(self, rho: ArrayLike) -> NDArray[np.float64]:
        """s'(ρ)/ρ, mm⁻¹: finite on the axis, where it equals 1/R (+ 2 a2 if any).

        Parameters
        ----------
        rho : array_like
            Radial coordinate ρ, mm, >= 0 (inside :meth:`max_rho`).
        """
        rho = np.asarray(rho, dtype=float)
        return 1.0 / self._q(rho) + self._poly(rho)[1]

    def slope(self, rho: ArrayLike) -> NDArray[np.float64]:
        """s'(ρ), dimensionless.

        Parameters
        ----------
        rho : array_like
            Radial coordinate ρ, mm, >= 0 (inside :meth:`max_rho`).
        """
        rho = np.asarray(rho, dtype=float)
        return rho * self.slope_over_rho(rho)

    def curvature(self, rho: ArrayLike) -> NDArray[np.float64]:
        """s''(ρ), mm⁻¹.

        Parameters
        ----------
        rho : array_like
            Radial coordinate ρ, mm, >= 0 (inside :meth:`max_rho`).
        """
        rho = np.asarray(rho, dtype=float)
        q = self._q(rho)
        return self.radius ** 2 / q ** 3 + self._poly(rho)[2]

    def normal_components(self, rho: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Unit outward normal in the meridional half-plane, as (n_ρ, n_z).

        ``n ∝ (s', 1)`` written as ``(ρ (1 + q p), q)`` with ``p`` the asphere's
        s'/ρ: finite at the axis and at a hemisphere's rim.

        Parameters
        ----------
        rho : array_like
            Radial coordinate ρ, mm, >= 0 (inside :meth:`max_rho`).
        """
        rho = np.asarray(rho, dtype=float)
        q = self._q(rho)
        p = self._poly(rho)[1]
        nr = rho * (1.0 + q * p)
        nz = q
        norm = np.hypot(nr, nz)
        return nr / norm, nz / norm

    def principal_radii(self, rho: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Principal radii of curvature (R_m, R_s) at ρ, mm.

        R_m (meridional, in the plane of the axis) = (1 + s'²)^{3/2} / s'' and
        R_s (sagittal) = ρ (1 + s'²)^{1/2} / s' — the distance along the normal from the
        surface to the axis. (The seed's Eq. 5 prints R_s = ρ (1+s'²)^{3/2}/s'', which
        is not a length.) Written through q: for a pure conic
        R_s = sqrt(R² − kρ²) and R_m = R_s³ / R²; both tend to R on the axis.

        Parameters
        ----------
        rho : array_like
            Radial coordinate ρ, mm, >= 0 (inside :meth:`max_rho`).
        """
        rho = np.asarray(rho, dtype=float)
        q = self._q(rho)
        _, p, p2 = self._poly(rho)
        h = 1.0 + q * p
        w = q * q + rho * rho * h * h  # q² (1 + s'²)
        r_s = np.sqrt(w) / h
        r_m = w ** 1.5 / (self.radius ** 2 + q ** 3 * p2)
        return r_m, r_s

    def max_rho(self) -> float:
        """Largest ρ in the conic's domain (inf for paraboloids and hyperboloids)."""
        return self.radius / np.sqrt(1.0 + self.conic) if 1.0 + self.conic > 0 else np.inf


def profile_of(mirror: Mirror) -> Profile:
    """The :class:`Profile` of a :class:`mitsweep.config.Mirror`.

    Parameters
    ----------
    mirror : mitsweep.config.Mirror
        The ``[mirror]`` table of a setup (kind, radius, conic, aspheric terms).
    """
    return Profile(radius=mirror.radius, conic=mirror.conic, aspheric=tuple(mirror.aspheric))
