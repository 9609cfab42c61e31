"""The mirror's outline on the sensor, as the setup predicts it.

The outline is the chief-ray image (:mod:`mitsweep.optics.chief_ray`) of the mirror's
rim, or of its limb where the camera sees past the surface before the rim (a
hemisphere), at the reference sensor distance (mid-travel of the sweep,
:mod:`mitsweep.optics.reference`). An untilted mirror's outline is a circle about the
axis; a tilted mirror's is not, and its axis point (the image of the vertex) is not the
outline's centre. :mod:`mitsweep.photo` finds it in a photograph.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config import Setup
from ..deprecation import renamed_keywords
from .chief_ray import chief_ray, image_point
from .placement import placement_of
from .reference import reference_geometry

__all__ = ["RimOutline", "predicted_outline"]


@dataclass(frozen=True)
class RimOutline:
    """The mirror's predicted outline on the sensor.

    Attributes
    ----------
    uv : (N, 2) ndarray
        Outline points ``(u, v)``, mm from the optical axis (upright image: u right,
        v up), in order around the outline.
    normal_uv : (N, 2) ndarray
        Outward unit normals in the same frame.
    sensor_distance : float
        Sensor distance (mm) the outline is predicted for.
    on_rim : (N,) bool ndarray
        True where the point is the rim's image, False where it is the limb's.
    """

    uv: np.ndarray
    normal_uv: np.ndarray
    sensor_distance: float
    on_rim: np.ndarray

    @renamed_keywords(pitch="pixel_pitch")
    def offsets_px(self, pixel_pitch: float) -> tuple[np.ndarray, np.ndarray]:
        """Points and outward normals as ``(drow, dcol)`` pixels from the axis, (N, 2).

        Parameters
        ----------
        pixel_pitch : float
            Pixel pitch, mm (the points are divided by it; the unit normals are not).
            Formerly ``pitch``, still accepted with a warning.
        """
        pts = np.stack([-self.uv[:, 1], self.uv[:, 0]], axis=-1) / pixel_pitch
        nrm = np.stack([-self.normal_uv[:, 1], self.normal_uv[:, 0]], axis=-1)
        return pts, nrm

    @renamed_keywords(pitch="pixel_pitch")
    def equivalent_radius_px(self, pixel_pitch: float) -> float:
        """Radius (px) of the circle of the outline's area (the radius, for a circle).

        Parameters
        ----------
        pixel_pitch : float
            Pixel pitch, mm (formerly ``pitch``, still accepted with a warning).
        """
        u, v = self.uv[:, 0], self.uv[:, 1]
        area = 0.5 * abs(np.dot(u, np.roll(v, -1)) - np.dot(v, np.roll(u, -1)))
        return math.sqrt(area / math.pi) / pixel_pitch


def _resample_closed(points: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` points evenly spaced by arc length along a closed polyline (N, 2), and for
    each the index of the polyline's vertex nearest along the arc."""
    closed = np.vstack([points, points[:1]])
    seg = np.linalg.norm(np.diff(closed, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    t = np.linspace(0.0, s[-1], n, endpoint=False)
    after = np.clip(np.searchsorted(s, t, side="right"), 1, len(s) - 1)
    nearest = np.where(t - s[after - 1] <= s[after] - t, after - 1, after) % len(points)
    return np.stack([np.interp(t, s, closed[:, 0]), np.interp(t, s, closed[:, 1])],
                    axis=-1), nearest


def predicted_outline(setup: Setup, *, sensor_distance: float | None = None,
                      n_points: int = 1440) -> RimOutline:
    """The outline of the mirror's image predicted by the setup.

    Parameters
    ----------
    setup : mitsweep.config.Setup
    sensor_distance : float, optional
        Lens–sensor distance, mm (default: the reference distance, mid-travel of the
        sweep, the distance whose image the centroid of a sweep photo's rim blur is).
    n_points : int
        Points along the outline (evenly spaced by arc length).

    Returns
    -------
    RimOutline

    Notes
    -----
    Along each meridian φ of the mirror the last point the lens sees is the rim, or
    the limb ``n·r̂ = 0`` where that comes first (found by bisection); the outline is
    the chief-ray image of those points. That is exact for an untilted mirror (the
    image radius grows with ρ up to the limb) and wherever the rim is visible all
    round (the paper's mirrors, the tilted paraboloid included).
    """
    if sensor_distance is None:
        sensor_distance = reference_geometry(setup).sensor_distance
    placement = placement_of(setup.mirror)
    rim = setup.mirror.rim_radius
    phi = np.linspace(0.0, 2.0 * math.pi, 4 * n_points, endpoint=False)

    def cos_inc(rho):
        surf = placement.surface(rho * np.cos(phi), rho * np.sin(phi))
        return chief_ray(placement, surf).cos_incidence

    rho_edge = np.full(phi.shape, rim)
    hidden = ~(cos_inc(rho_edge) > 0)
    if np.any(hidden):  # the limb comes before the rim on these meridians: bisect
        lo, hi = np.zeros(phi.shape), np.full(phi.shape, rim)
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            vis = cos_inc(mid) > 0
            lo, hi = np.where(vis, mid, lo), np.where(vis, hi, mid)
        rho_edge = np.where(hidden, lo, rim)
    surf = placement.surface(rho_edge * np.cos(phi), rho_edge * np.sin(phi))
    u, v = image_point(chief_ray(placement, surf), sensor_distance)
    dense = np.stack([u, v], axis=-1)
    uv, nearest = _resample_closed(dense, n_points)
    tangent = np.roll(uv, -1, axis=0) - np.roll(uv, 1, axis=0)
    normal = np.stack([tangent[:, 1], -tangent[:, 0]], axis=-1)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    centroid = uv.mean(axis=0)
    normal *= np.where(np.sum((uv - centroid) * normal, axis=-1) < 0, -1.0, 1.0)[:, None]
    # Which resampled points are rim (not limb): the flag of the dense sample nearest
    # along the outline (the nearest in the plane, found over all pairs, cost 0.1 s).
    return RimOutline(uv=uv, normal_uv=normal, sensor_distance=float(sensor_distance),
                      on_rim=~hidden[nearest])
