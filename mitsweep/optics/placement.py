"""Placement of the mirror relative to the camera, and points on the mirror.

World frame (docs/design.md): the mirror vertex at the origin, its untilted axis +z toward
the camera, the lens centre at ``(0, 0, vertex_distance)``; the camera looks down −z,
image right = world +x, image up = world +y. Tilt rotates the mirror about its vertex in
the x–z plane: the local axis becomes ``(sin t, 0, cos t)``, so for t > 0 the mirror's
−x rim moves toward the camera.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..config import Mirror
from .profiles import Profile, profile_of

__all__ = ["Placement", "placement_of", "SurfacePoints"]


@dataclass(frozen=True)
class SurfacePoints:
    """Points on the mirror in world coordinates with their local description.

    Attributes
    ----------
    position, normal : (..., 3) ndarray
        World position (mm) and unit outward normal.
    rho : (...) ndarray
        Local radial coordinate, mm.
    radial_dir : (..., 3) ndarray
        World unit vector of the local radial (meridional) direction, tangent to the
        surface; undefined (x) on the axis.
    """

    position: np.ndarray
    normal: np.ndarray
    rho: np.ndarray
    radial_dir: np.ndarray


@dataclass(frozen=True)
class Placement:
    """A mirror profile placed in front of the lens.

    Parameters
    ----------
    profile : Profile
        The mirror's surface in its own frame (vertex at the origin, axis +z).
    vertex_distance : float
        Lens centre to mirror vertex, mm.
    tilt : float, optional
        Rotation of the mirror about its vertex in the x–z plane, radians.
    rim_radius : float, optional
        Radial extent of the mirror, mm (``inf``: unbounded).
    """

    profile: Profile
    vertex_distance: float
    tilt: float = 0.0  # radians
    rim_radius: float = np.inf

    @property
    def lens_center(self) -> np.ndarray:
        return np.array([0.0, 0.0, self.vertex_distance])

    @property
    def rotation(self) -> np.ndarray:
        """Local-to-world rotation (about y by the tilt)."""
        c, s = np.cos(self.tilt), np.sin(self.tilt)
        return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])

    @property
    def axis(self) -> np.ndarray:
        return self.rotation[:, 2]

    def to_local(self, p: ArrayLike) -> np.ndarray:
        """World points (..., 3) to the mirror's local frame.

        Parameters
        ----------
        p : (..., 3) array_like
            World coordinates, mm (or directions: the map is a rotation about the
            vertex, the origin of both frames).
        """
        return np.asarray(p, dtype=float) @ self.rotation

    def to_world(self, p: ArrayLike) -> np.ndarray:
        """Local points (..., 3) to world coordinates, the inverse of :meth:`to_local`.

        Parameters
        ----------
        p : (..., 3) array_like
            Coordinates in the mirror's frame (vertex at the origin, axis +z), mm (or
            directions).
        """
        return np.asarray(p, dtype=float) @ self.rotation.T

    def surface(self, x: ArrayLike, y: ArrayLike) -> SurfacePoints:
        """World points and normals at local coordinates (x, y), mm (broadcast).

        Parameters
        ----------
        x, y : array_like
            Local coordinates across the mirror's axis, mm; the point is on the surface
            at ``z = −sag(ρ)``, ``ρ = hypot(x, y)``.
        """
        x, y = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
        rho = np.hypot(x, y)
        z = -self.profile.sag(rho)
        nr, nz = self.profile.normal_components(rho)
        safe = np.where(rho > 0, rho, 1.0)
        cx, cy = np.where(rho > 0, x / safe, 1.0), np.where(rho > 0, y / safe, 0.0)
        local_p = np.stack([x, y, z], axis=-1)
        local_n = np.stack([nr * cx, nr * cy, nz], axis=-1)
        # Tangent along increasing ρ: (cos φ, sin φ, −s') normalised = (nz cφ, nz sφ, −nr).
        local_t = np.stack([nz * cx, nz * cy, -nr], axis=-1)
        return SurfacePoints(self.to_world(local_p), self.to_world(local_n), rho,
                             self.to_world(local_t))


def placement_of(mirror: Mirror) -> Placement:
    """The :class:`Placement` of a :class:`mitsweep.config.Mirror`.

    Parameters
    ----------
    mirror : mitsweep.config.Mirror
        The ``[mirror]`` table of a setup.
    """
    return Placement(profile_of(mirror), mirror.vertex_distance, mirror.tilt, mirror.rim_radius)
