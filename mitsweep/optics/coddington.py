"""Generalised Coddington equations for reflection (paper Eq. 4–7).

For a world point at distance ``l`` from the reflecting point, a mirror whose principal
radii at that point are ``R_m`` (in the plane of incidence) and ``R_s`` (across it),
and ``c = n̂·r̂`` the cosine of the angle of incidence, the convex mirror forms two
virtual focal images behind it, on the chief ray, at distances

.. math::

    d_m = \\frac{l R_m c}{2 l + R_m c} = \\frac{R_m c}{2 + R_m c / l}, \\qquad
    d_s = \\frac{l R_s}{2 l c + R_s} = \\frac{R_s}{2 c + R_s / l}.

The second forms take ``l = ∞`` exactly (``d_m = R_m c / 2``, the caustic of
Swaminathan). They hold where the plane of incidence contains a principal direction:
every point of a mirror seen on its axis, and the tilt plane of a tilted one. The
general form is Burkhard and Shealy's [1]_; the paper states it as its Eq. 4–7 [2]_.

References
----------
.. [1] D. G. Burkhard and D. L. Shealy, "Simplified formula for the illuminance in an
   optical system", Applied Optics 20(5), 1981.
.. [2] R. Yokoya and S. K. Nayar, "Extended depth of field catadioptric imaging using
   focal sweep", Eq. 4–7.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..config import Setup

from .chief_ray import chief_ray
from .placement import placement_of

__all__ = ["coddington_reflection", "focal_distances", "focal_image_axial_distances"]


def coddington_reflection(r_m: ArrayLike, r_s: ArrayLike, cos_incidence: ArrayLike,
                          depth: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(d_m, d_s), mm, from principal radii, incidence cosine and depth (inf allowed).

    Parameters
    ----------
    r_m, r_s : array_like
        Meridional and sagittal principal radii of curvature of the mirror, mm.
    cos_incidence : array_like
        Cosine of the chief ray's angle of incidence.
    depth : array_like
        Object distance l along the reflected ray, mm (``inf`` allowed).
    """
    r_m, r_s, c, l = (np.asarray(a, dtype=float) for a in (r_m, r_s, cos_incidence, depth))
    inv_l = np.where(np.isinf(l), 0.0, 1.0 / l)
    d_m = r_m * c / (2.0 + r_m * c * inv_l)
    d_s = r_s / (2.0 * c + r_s * inv_l)
    return d_m, d_s


def _surface_points(setup, rho):
    """Mirror points at (signed, tilt-plane) local coordinate ρ, with their chief rays."""
    placement = placement_of(setup.mirror)
    rho = np.asarray(rho, dtype=float)
    surf = placement.surface(rho, np.zeros_like(rho))
    return placement, chief_ray(placement, surf)


def focal_distances(setup: Setup, rho: ArrayLike, depth: ArrayLike
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Distances (d_m, d_s), mm, from the mirror point at ``rho`` to its focal images.

    Parameters
    ----------
    setup : mitsweep.config.Setup
    rho : array_like
        Radial coordinate of the mirror point, mm. For a tilted mirror, the signed local
        x coordinate of a point in the tilt plane.
    depth : array_like
        Distance l from the mirror point to the world point along the world-bound
        reflected chief ray, mm (``inf`` allowed). Broadcast against ``rho``.

    Returns
    -------
    d_m, d_s : ndarray
        Meridional and sagittal distances (paper Eq. 4 and 5 with the sagittal radius
        corrected to ρ (1 + f'²)^{1/2} / f').
    """
    depth = np.asarray(depth, dtype=float)
    if np.any(~(depth > 0)):
        raise ValueError(f"depth must be > 0 mm (inf allowed), got {float(np.min(depth))!r}")
    rho = np.asarray(rho, dtype=float)
    if np.any(np.abs(rho) > setup.mirror.rim_radius):
        raise ValueError(f"rho must lie within the rim (|rho| <= {setup.mirror.rim_radius:g} mm), "
                         f"got {float(np.max(np.abs(rho))):g}")
    placement, ray = _surface_points(setup, rho)
    r_m, r_s = placement.profile.principal_radii(np.abs(rho))
    return coddington_reflection(r_m, r_s, ray.cos_incidence, depth)


def focal_image_axial_distances(setup: Setup, rho: ArrayLike, depth: ArrayLike
                               ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(D_m, D_s), mm: axial distances from the lens to the focal images (Eq. 6–7).

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The mirror, lens and placement.
    rho : array_like
        Mirror points as signed tilt-plane coordinates, mm.
    depth : array_like
        Depths l, mm (``inf`` allowed); broadcast with ``rho``.
    """
    placement, ray = _surface_points(setup, rho)
    d_m, d_s = focal_distances(setup, rho, depth)
    p, r = ray.surface.position, ray.to_lens
    # v̂ = −z: D = |(p_r − d r̂ − p_c)·v̂| = p_c,z − p_r,z + d r̂_z.
    base = placement.vertex_distance - p[..., 2]
    return np.abs(base + d_m * r[..., 2]), np.abs(base + d_s * r[..., 2])
