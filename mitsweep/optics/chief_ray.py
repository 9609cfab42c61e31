"""The chief ray: image point ↔ mirror point ↔ world-bound reflected direction.

The chief ray passes through the lens centre ``p_c``. For a mirror point ``p_r`` with
outward normal ``n``: ``r̂ = (p_c − p_r)/|p_c − p_r|`` (the reflected light heading for
the lens; paper Fig. 2), the camera ray arrives along ``−r̂``, and the world-bound
reflected ray leaves along ``w = −r̂ + 2 (n·r̂) n``. A world point at depth ``l`` is
``p_r + l w``. The image of ``p_r`` on a sensor at distance ``i`` behind the lens, in the
image's own (upright) coordinates, is ``(u, v) = −i (r̂_x, r̂_y) / r̂_z``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .placement import Placement, SurfacePoints

__all__ = ["ChiefRay", "chief_ray", "intersect_mirror", "mirror_point_from_image",
           "image_point"]


@dataclass(frozen=True)
class ChiefRay:
    """Chief-ray quantities at mirror points (arrays broadcast over the points).

    Attributes
    ----------
    surface : SurfacePoints
        The mirror points (position, normal, ρ), as the profile gives them.
    to_lens : ndarray, shape (..., 3)
        Unit vector r̂ from each mirror point toward the lens centre.
    world_dir : ndarray, shape (..., 3)
        Unit direction w of the world-bound reflected chief ray.
    cos_incidence : ndarray
        n·r̂, the cosine of the angle of incidence (> 0 where the camera sees the front).
    lens_distance : ndarray
        Distance ``|p_c − p_r|`` from the lens centre to the mirror point, mm.
    """

    surface: SurfacePoints
    to_lens: np.ndarray      # r̂, (..., 3)
    world_dir: np.ndarray    # w, (..., 3)
    cos_incidence: np.ndarray  # n·r̂
    lens_distance: np.ndarray  # |p_c − p_r|

    @property
    def visible(self) -> np.ndarray:
        """The camera sees the front of the mirror here (n·r̂ > 0)."""
        return self.cos_incidence > 0


def chief_ray(placement: Placement, surface: SurfacePoints) -> ChiefRay:
    """Chief-ray quantities for points ``surface`` of ``placement``'s mirror.

    Parameters
    ----------
    placement : Placement
        The mirror profile placed in front of the lens.
    surface : SurfacePoints
        Points of that profile (e.g. from ``placement.profile``), in the mirror's frame.

    Returns
    -------
    ChiefRay
        Arrays broadcast over the points.
    """
    to_lens = placement.lens_center - surface.position
    dist = np.linalg.norm(to_lens, axis=-1)
    r = to_lens / dist[..., None]
    c = np.sum(surface.normal * r, axis=-1)
    w = -r + 2.0 * c[..., None] * surface.normal
    w = w / np.linalg.norm(w, axis=-1)[..., None]
    return ChiefRay(surface, r, w, c, dist)


def image_point(ray: ChiefRay, sensor_distance: float
               ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Upright image coordinates (u, v), mm, of the mirror points on a sensor at ``i``.

    Parameters
    ----------
    ray : ChiefRay
        Chief rays at the mirror points (:func:`chief_ray`).
    sensor_distance : float
        Lens-to-sensor distance i, mm.
    """
    r = ray.to_lens
    return (-sensor_distance * r[..., 0] / r[..., 2], -sensor_distance * r[..., 1] / r[..., 2])


def intersect_mirror(placement: Placement, origin: ArrayLike, direction: ArrayLike, *,
                     newton_iters: int = 8) -> NDArray[np.float64]:
    """First intersection of rays with the mirror (front side, within the rim).

    Solves the conic ``(1+k) z² + 2 R z + x² + y² = 0`` (local frame) with a
    cancellation-free quadratic formula, keeps the root on the mirror's branch
    (``R + (1+k) z ≥ 0``) nearest the origin, then refines for asphere terms by Newton
    steps on ``z + s(ρ) = 0``.

    Parameters
    ----------
    placement : Placement
        The mirror and where it sits.
    origin : array_like, shape (..., 3)
        Ray origins, mm, in the camera frame (lens centre at the origin).
    direction : array_like, shape (..., 3)
        Ray directions (need not be unit length; ``t`` is in their units).
    newton_iters : int, optional
        Newton steps that refine the conic's root for the asphere terms.

    Returns
    -------
    t : ndarray
        Ray parameter of the hit, ``inf`` where the ray misses (or hits outside the rim).
    """
    o = placement.to_local(np.asarray(origin, dtype=float))
    d = placement.to_local(np.asarray(direction, dtype=float))
    o, d = np.broadcast_arrays(o, d)
    R, k = placement.profile.radius, placement.profile.conic
    ok = 1.0 + k
    a = d[..., 0] ** 2 + d[..., 1] ** 2 + ok * d[..., 2] ** 2
    b = 2.0 * (o[..., 0] * d[..., 0] + o[..., 1] * d[..., 1] + ok * o[..., 2] * d[..., 2]
               + R * d[..., 2])
    c = o[..., 0] ** 2 + o[..., 1] ** 2 + ok * o[..., 2] ** 2 + 2.0 * R * o[..., 2]
    disc = b * b - 4.0 * a * c
    with np.errstate(invalid="ignore", divide="ignore"):
        sq = np.sqrt(np.where(disc >= 0, disc, np.nan))
        qq = -0.5 * (b + np.copysign(sq, b))
        t1 = qq / a
        t2 = c / qq
        lin = np.abs(a) < 1e-14 * (np.abs(b) + 1e-300)
        t1 = np.where(lin, -c / b, t1)
        t2 = np.where(lin, np.inf, t2)
    best = np.full(a.shape, np.inf)
    with np.errstate(invalid="ignore"):  # NaN roots (misses) compare False
        for t in (t1, t2):
            z = o[..., 2] + t * d[..., 2]
            on_branch = (R + ok * z) >= -1e-9 * R
            good = np.isfinite(t) & (t > 0) & on_branch
            best = np.where(good & (t < best), t, best)
    if any(placement.profile.aspheric):
        prof = placement.profile
        t = np.where(np.isfinite(best), best, 0.0)
        for _ in range(newton_iters):
            p = o + t[..., None] * d
            rho = np.hypot(p[..., 0], p[..., 1])
            f = p[..., 2] + prof.sag(rho)
            g = prof.slope_over_rho(rho)
            df = d[..., 2] + g * (p[..., 0] * d[..., 0] + p[..., 1] * d[..., 1])
            t = t - f / df
        best = np.where(np.isfinite(best), t, np.inf)
    p = o + np.where(np.isfinite(best), best, 0.0)[..., None] * d
    inside = np.hypot(p[..., 0], p[..., 1]) <= placement.rim_radius * (1 + 1e-12)
    return np.where(inside, best, np.inf)


def mirror_point_from_image(placement: Placement, u: ArrayLike, v: ArrayLike,
                            sensor_distance: float) -> ChiefRay:
    """Chief rays through upright image points (u, v) mm on a sensor at distance ``i``.

    Points whose chief ray misses the mirror get NaN positions (check
    ``np.isfinite(ray.surface.rho)``).

    Parameters
    ----------
    placement : Placement
        The mirror and where it sits.
    u, v : array_like
        Upright image coordinates, mm (broadcast together).
    sensor_distance : float
        Lens-to-sensor distance i, mm, at which (u, v) are measured.

    Returns
    -------
    ChiefRay
        The chief rays through those image points and the mirror points they hit.
    """
    u, v = np.broadcast_arrays(np.asarray(u, dtype=float), np.asarray(v, dtype=float))
    d = np.stack([u, v, -np.full_like(u, sensor_distance)], axis=-1)
    d = d / np.linalg.norm(d, axis=-1)[..., None]
    c = placement.lens_center
    t = intersect_mirror(placement, c, d)
    hit = np.isfinite(t)
    p = c + np.where(hit, t, np.nan)[..., None] * d
    local = placement.to_local(p)
    surf = placement.surface(local[..., 0], local[..., 1])
    return chief_ray(placement, surf)
