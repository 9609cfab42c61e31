"""Point sources as in the paper: a world point at depth l along a reflected chief ray.

The image point ↔ mirror point correspondence uses the chief-ray solution of
:mod:`mitsweep.optics` (shared setup math); the rays themselves are generated and
intersected by :mod:`mitsweep.tracer.kernel` only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config import Setup
from ..optics import chief_ray, image_point, mirror_point_from_image, placement_of
from .kernel import Geometry

__all__ = ["PointSource", "source_from_image", "source_from_mirror", "check_depth"]


def check_depth(depth: float) -> float:
    """Validate a depth l (mm, > 0, inf allowed) and return it as float.

    Parameters
    ----------
    depth : float
        Depth l of a point source along its reflected chief ray, mm.

    Returns
    -------
    float

    Raises
    ------
    ValueError
        Not a number, NaN, or not > 0.
    """
    try:
        d = float(depth)
    except (TypeError, ValueError):
        raise ValueError(f"depth: expected a distance in mm, got {depth!r}") from None
    if not d > 0:  # also NaN
        raise ValueError(f"depth: must be > 0 mm (inf allowed), got {depth!r}")
    return d


@dataclass(frozen=True)
class PointSource:
    """A point source and the chief ray it is seen along.

    Attributes
    ----------
    mirror_point : (3,) ndarray
        p_r, world, mm.
    local_point : (3,) ndarray
        p_r in the mirror's local frame, mm.
    world_dir : (3,) ndarray
        w, the world-bound reflected chief direction (unit, world).
    normal : (3,) ndarray
        The mirror's unit normal at p_r, world.
    depth : float
        l, mm (inf allowed).
    position : (3,) ndarray
        ``p_r + l w`` (world, mm; inf components for l = inf).
    image_uv : tuple of float
        Chief-ray image (u, v), mm, at the reference sensor distance.
    reference_sensor_distance : float
        mm.
    cos_incidence : float
        n·r̂ at p_r.
    """

    mirror_point: np.ndarray
    local_point: np.ndarray
    world_dir: np.ndarray
    normal: np.ndarray
    depth: float
    image_uv: tuple
    reference_sensor_distance: float
    cos_incidence: float

    @property
    def position(self) -> np.ndarray:
        return self.mirror_point + self.depth * self.world_dir

    def geometry(self, setup: Setup, *, rim: bool = True,
                 aperture_radius: float | None = None) -> Geometry:
        """The kernel's :class:`Geometry` for this source (local frame, float64).

        Parameters
        ----------
        setup : mitsweep.config.Setup
            The mirror and lens this source was found with.
        rim : bool, optional
            Keep the mirror's rim (default True); False sets an infinite rim (to measure
            vignetting).
        aperture_radius : float, optional
            Override the lens aperture radius, mm.

        Returns
        -------
        Geometry
        """
        m = setup.mirror
        pl = placement_of(m)
        rot = pl.rotation
        w_l = self.world_dir @ rot
        n_l = self.normal @ rot
        e1 = n_l - (n_l @ w_l) * w_l
        if np.linalg.norm(e1) < 1e-9:  # n ∥ w (axis point): any perpendicular will do
            e1 = np.array([1.0, 0.0, 0.0]) - w_l[0] * w_l
        e1 = e1 / np.linalg.norm(e1)
        e2 = np.cross(w_l, e1)
        rim_r = m.rim_radius
        sag_rim = float(pl.profile.sag(min(rim_r, pl.profile.max_rho())))
        margin = float(np.linalg.norm(self.local_point) + math.hypot(rim_r, sag_rim) + 1.0)
        return Geometry(
            radius=m.radius, conic=m.conic, aspheric=tuple(m.aspheric),
            rim_radius=rim_r if rim else math.inf, rotation=rot,
            vertex_distance=m.vertex_distance, focal_length=setup.lens.focal_length,
            aperture_radius=setup.lens.aperture_radius if aperture_radius is None
            else float(aperture_radius),
            origin_pr=self.local_point, w=w_l, e1=e1, e2=e2, depth=self.depth, margin=margin)


def _from_ray(ray, depth: float, reference: float, placement) -> PointSource:
    u, v = image_point(ray, reference)
    p = np.asarray(ray.surface.position, dtype=float).reshape(3)
    return PointSource(
        mirror_point=p, local_point=placement.to_local(p),
        world_dir=np.asarray(ray.world_dir, dtype=float).reshape(3),
        normal=np.asarray(ray.surface.normal, dtype=float).reshape(3),
        depth=depth, image_uv=(float(u), float(v)), reference_sensor_distance=reference,
        cos_incidence=float(ray.cos_incidence))


def source_from_image(setup: Setup, u: float, v: float, depth: float, *,
                      reference_sensor_distance: float) -> PointSource:
    """The source seen at upright image point (u, v) mm on a sensor at the reference distance.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The mirror and lens.
    u, v : float
        Upright image coordinates of the chief-ray image, mm.
    depth : float
        Depth l along the reflected chief ray, mm (> 0, inf allowed).
    reference_sensor_distance : float
        The sensor distance (u, v) are measured at, mm.

    Returns
    -------
    PointSource

    Raises
    ------
    ValueError
        If the chief ray through (u, v) misses the mirror or sees its back, or the depth
        is not > 0.
    """
    depth = check_depth(depth)
    pl = placement_of(setup.mirror)
    ray = mirror_point_from_image(pl, np.array(float(u)), np.array(float(v)),
                                  reference_sensor_distance)
    if not np.all(np.isfinite(ray.surface.position)) or not float(ray.cos_incidence) > 0:
        # The image of the mirror is the disk of its rim's chief rays.
        rim = setup.mirror.rim_radius
        edge = chief_ray(pl, pl.surface(np.array([rim]), np.array([0.0])))
        ue, _ = image_point(edge, reference_sensor_distance)
        raise ValueError(f"image point (u, v) = ({u:g}, {v:g}) mm is outside the mirror's image "
                         f"(its chief ray misses the mirror; the rim images at about "
                         f"|u| = {abs(float(ue[0])):.3f} mm on a sensor at "
                         f"{reference_sensor_distance:.3f} mm)")
    return _from_ray(ray, depth, reference_sensor_distance, pl)


def source_from_mirror(setup: Setup, x: float, y: float, depth: float, *,
                       reference_sensor_distance: float) -> PointSource:
    """The source seen at the mirror point of local coordinates (x, y), mm.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The mirror and lens.
    x, y : float
        The mirror point in the mirror's local frame, mm, within the rim.
    depth : float
        Depth l along the reflected chief ray, mm (> 0, inf allowed).
    reference_sensor_distance : float
        The sensor distance at which ``image_uv`` is given, mm.

    Returns
    -------
    PointSource

    Raises
    ------
    ValueError
        The point lies outside the rim or faces away from the lens, or the depth is not
        > 0.
    """
    depth = check_depth(depth)
    pl = placement_of(setup.mirror)
    if math.hypot(x, y) > setup.mirror.rim_radius:
        raise ValueError(f"mirror point ({x:g}, {y:g}) mm lies outside the rim "
                         f"({setup.mirror.rim_radius:g} mm)")
    ray = chief_ray(pl, pl.surface(np.array(float(x)), np.array(float(y))))
    if not float(ray.cos_incidence) > 0:
        raise ValueError(f"mirror point ({x:g}, {y:g}) mm is not visible from the lens")
    return _from_ray(ray, depth, reference_sensor_distance, pl)
