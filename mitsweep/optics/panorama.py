"""Panoramas from the mirror geometry: the exact unwarping of a catadioptric image.

Every pixel of a catadioptric image sees the world along one direction, the world-bound
reflected chief ray of the mirror point its chief ray meets (:mod:`.chief_ray`). mitsweep
knows the mirror exactly, so the two maps between image and panorama are computed from
that geometry, not fitted:

- **inverse** (image → panorama): pixel → sensor point (:mod:`.pixels`) → chief ray →
  ray–mirror intersection → reflected direction → panorama coordinates;
- **forward** (panorama → image): panorama coordinates → direction → the mirror point
  that reflects it toward the lens, solved by Newton's method on the mirror's local
  ``(x, y)`` (seeded from a table of mirror points) → its chief-ray image.

Both are exact up to the solver's tolerance (residual direction < 1e-11 rad), so a round
trip agrees to far better than 0.01 px.

Panorama coordinates
--------------------
The pole is the camera axis, world +z (for an untilted mirror also the mirror's axis),
the direction in which the mirror shows the camera itself. A direction of azimuth φ
(from world +x toward +y) and elevation ε (above the plane z = 0, toward the camera) is

.. math:: \\hat w = (\\cos ε \\cos φ,\\ \\cos ε \\sin φ,\\ \\sin ε).

Columns run clockwise seen from the camera, so the panorama reads as the world seen from
the mirror with the camera overhead (not mirror-reversed); it wraps without a seam:

.. math:: φ(c) = π - 2π\\,(c + \\tfrac12) / W_p .

Rows run from the top elevation ``ε_hi`` down to ``ε_lo``: linear in ε
(``equirectangular``) or in ``tan ε``, the height on a unit cylinder (``cylindrical``,
which cannot reach ±90°).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .chief_ray import chief_ray, image_point, mirror_point_from_image
from .pixels import center_offset_of, optical_center_px, pixel_to_sensor, sensor_to_pixel
from ..config import Setup
from .placement import Placement

__all__ = ["PROJECTIONS", "UP_CHOICES", "PanoramaMap", "panorama_map", "direction_to_image",
           "image_to_direction", "directions_to_angles", "angles_to_directions", "unwarp",
           "CYLINDRICAL_TOP_DEG"]

logger = logging.getLogger(__name__)

PROJECTIONS = ("cylindrical", "equirectangular")
#: Which way is up in the panorama: ``"camera"``, toward the camera (the pole the camera
#: sees itself at): world-up for a camera above the mirror looking down at it;
#: ``"away"``, away from the camera: world-up for a camera below the mirror looking up
#: at it (the panorama turned by 180°, so that it stays unmirrored).
UP_CHOICES = ("camera", "away")
#: Default top elevation of a cylindrical panorama, degrees: its height ``tan ε`` grows
#: without bound toward the pole (tan 75° = 3.7 cylinder radii).
CYLINDRICAL_TOP_DEG = 75.0
#: Newton's method: iterations and the residual (rad) below which a direction is solved.
_NEWTON_ITERS = 30
_NEWTON_TOL = 1e-11
#: Seed table of mirror points (radii x azimuths) for the forward map's solver.
_SEED_RADII, _SEED_AZIMUTHS = 160, 320


def angles_to_directions(azimuth: ArrayLike, elevation: ArrayLike) -> np.ndarray:
    """Unit world directions (..., 3) of azimuth φ and elevation ε, radians.

    Parameters
    ----------
    azimuth : array_like
        φ, radians, from world +x toward +y.
    elevation : array_like
        ε, radians, above the plane z = 0 (toward the camera); broadcast with
        ``azimuth``.
    """
    az, el = np.broadcast_arrays(np.asarray(azimuth, float), np.asarray(elevation, float))
    ce = np.cos(el)
    return np.stack([ce * np.cos(az), ce * np.sin(az), np.sin(el)], axis=-1)


def directions_to_angles(directions: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(azimuth φ in (−π, π], elevation ε in [−π/2, π/2]), radians, of directions (..., 3).

    Parameters
    ----------
    directions : (..., 3) array_like
        World directions (need not be unit).
    """
    d = np.asarray(directions, dtype=float)
    return (np.arctan2(d[..., 1], d[..., 0]),
            np.arctan2(d[..., 2], np.hypot(d[..., 0], d[..., 1])))


def image_to_direction(placement: Placement, u: ArrayLike, v: ArrayLike, sensor_distance: float
                       ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """World directions seen at upright image points (u, v), mm, on a sensor at ``i``.

    Parameters
    ----------
    placement : Placement
        The mirror in front of the lens.
    u, v : array_like
        Upright image coordinates, mm from the optical axis (u right, v up), broadcast
        together.
    sensor_distance : float
        Lens-to-sensor distance ``i`` of the image, mm.

    Returns
    -------
    directions : (..., 3) ndarray
        Unit world-bound reflected chief rays; NaN where the chief ray misses the mirror
        or meets its back.
    valid : (...) bool ndarray
    """
    ray = mirror_point_from_image(placement, u, v, sensor_distance)
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(ray.surface.rho) & (ray.cos_incidence > 0)
    w = np.where(valid[..., None], ray.world_dir, np.nan)
    return w, valid


def _world_dir_at(placement: Placement, x, y) -> np.ndarray:
    return chief_ray(placement, placement.surface(x, y)).world_dir


def _seed_table(placement: Placement):
    """Visible mirror points (local x, y) and their reflected directions."""
    from scipy.spatial import cKDTree

    rim = min(placement.rim_radius, placement.profile.max_rho())
    rho = rim * np.linspace(0.0, 1.0, _SEED_RADII)[:, None] * (1 - 1e-9)
    phi = np.linspace(-np.pi, np.pi, _SEED_AZIMUTHS, endpoint=False)[None, :]
    x, y = (rho * np.cos(phi)).ravel(), (rho * np.sin(phi)).ravel()
    ray = chief_ray(placement, placement.surface(x, y))
    ok = (ray.cos_incidence > 0) & np.all(np.isfinite(ray.world_dir), axis=-1)
    tree = cKDTree(ray.world_dir[ok])
    # no direction the mirror shows is farther than about a table spacing from the table
    reach = 3.0 * float(tree.query(ray.world_dir[ok], k=2)[0][:, 1].max())
    return tree, np.stack([x[ok], y[ok]], axis=-1), reach


def direction_to_image(placement: Placement, directions: ArrayLike, sensor_distance: float
                       ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Upright image points (u, v), mm, where world ``directions`` are seen.

    Solves ``ŵ(x, y) = d`` for the mirror point (local ``x, y``) by Newton's method on the
    two components of ``ŵ`` across ``d`` (finite-difference Jacobian), seeded by the
    nearest of a table of mirror points, then images that point (:func:`image_point`).

    Parameters
    ----------
    placement : Placement
    directions : (..., 3) array_like
        World directions (need not be unit).
    sensor_distance : float
        Lens-to-sensor distance of the image, mm.

    Returns
    -------
    u, v : (...) ndarray
        NaN where the mirror does not show the direction (behind it, beyond its rim, or
        hidden from the lens).
    valid : (...) bool ndarray
    """
    d = np.asarray(directions, dtype=float)
    shape = d.shape[:-1]
    t = (d / np.linalg.norm(d, axis=-1, keepdims=True)).reshape(-1, 3)
    n = t.shape[0]
    u = np.full(n, np.nan)
    v = np.full(n, np.nan)
    valid = np.zeros(n, bool)
    if n == 0:
        return u.reshape(shape), v.reshape(shape), valid.reshape(shape)
    tree, table, reach = _seed_table(placement)
    gap, idx = tree.query(t, distance_upper_bound=reach)  # unbounded: slow far off
    xy = table[np.minimum(idx, len(table) - 1)].copy()
    # an orthonormal basis (e1, e2) across each target direction
    helper = np.where(np.abs(t[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    e1 = np.cross(t, helper)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(t, e1)
    rim = min(placement.rim_radius, placement.profile.max_rho())
    h = 1e-6 * max(rim, 1.0)
    r_max = rim - 2 * h

    def clamp(p):
        rho = np.hypot(p[:, 0], p[:, 1])
        scale = np.where(rho > r_max, r_max / np.maximum(rho, 1e-300), 1.0)
        return p * scale[:, None]

    def residual(p, rows):
        w = _world_dir_at(placement, p[:, 0], p[:, 1])
        return np.stack([np.sum(w * e1[rows], -1), np.sum(w * e2[rows], -1)], -1), w

    active = np.flatnonzero(gap <= reach)  # the others are not on the mirror
    res = np.full(n, np.inf)
    for _ in range(_NEWTON_ITERS):
        if active.size == 0:
            break
        p = clamp(xy[active])
        f, w = residual(p, active)
        res[active] = np.where(np.sum(w * t[active], -1) > 0, np.hypot(f[:, 0], f[:, 1]),
                               np.inf)
        todo = res[active] > _NEWTON_TOL
        active, p, f = active[todo], p[todo], f[todo]
        if active.size == 0:
            break
        fx, _ = residual(p + [h, 0.0], active)
        fy, _ = residual(p + [0.0, h], active)
        jx, jy = (fx - f) / h, (fy - f) / h
        det = jx[:, 0] * jy[:, 1] - jy[:, 0] * jx[:, 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            dx = -(jy[:, 1] * f[:, 0] - jy[:, 0] * f[:, 1]) / det
            dy = -(-jx[:, 1] * f[:, 0] + jx[:, 0] * f[:, 1]) / det
        step = np.stack([dx, dy], -1)
        # damp steps longer than a tenth of the rim (far from the solution)
        length = np.hypot(step[:, 0], step[:, 1])
        step *= np.where(length > 0.1 * rim, 0.1 * rim / np.maximum(length, 1e-300), 1.0)[:, None]
        step = np.where(np.isfinite(step), step, 0.0)
        xy[active] = clamp(p + step)
    xy = clamp(xy)
    ray = chief_ray(placement, placement.surface(xy[:, 0], xy[:, 1]))
    ok = (res <= _NEWTON_TOL) & (ray.cos_incidence > 0)
    ok &= np.hypot(xy[:, 0], xy[:, 1]) < r_max
    uu, vv = image_point(ray, sensor_distance)
    u[ok], v[ok], valid[ok] = uu[ok], vv[ok], True
    return u.reshape(shape), v.reshape(shape), valid.reshape(shape)


@dataclass(frozen=True)
class PanoramaMap:
    """The two maps between one catadioptric image and one panorama of it.

    Attributes
    ----------
    placement : Placement
        The mirror in front of the lens.
    sensor_distance : float
        Sensor distance of the image's pixel grid, mm (an EDOF image: the reference
        distance, :mod:`.reference`).
    image_shape : (H, W)
    pixel_pitch : float
        mm.
    center_px : (row, col)
        Where the camera axis meets the image (default the image centre).
    projection : {"cylindrical", "equirectangular"}
    size : (W_p, H_p)
        Panorama columns and rows.
    elevation_range : (ε_lo, ε_hi)
        Radians: the bottom and top of the panorama (the top and bottom with
        ``up="away"``).
    up : {"camera", "away"}
        Which way is up (:data:`UP_CHOICES`): toward the camera (default; world-up for
        a camera looking down at the mirror) or away from it (a camera looking up at
        it), where the panorama is turned by 180°.
    """

    placement: Placement
    sensor_distance: float
    image_shape: tuple[int, int]
    pixel_pitch: float
    center_px: tuple[float, float]
    projection: str
    size: tuple[int, int]
    elevation_range: tuple[float, float]
    up: str = "camera"

    def __post_init__(self) -> None:
        if self.up not in UP_CHOICES:
            raise ValueError(f"up: must be one of {', '.join(UP_CHOICES)}, got {self.up!r}")
        if self.projection not in PROJECTIONS:
            raise ValueError(f"projection: must be one of {', '.join(PROJECTIONS)}, got "
                             f"{self.projection!r}")
        lo, hi = self.elevation_range
        if not -math.pi / 2 <= lo < hi <= math.pi / 2:
            raise ValueError(f"elevation range: need -90 <= low < high <= 90 degrees, got "
                             f"{math.degrees(lo):g}, {math.degrees(hi):g}")
        if self.projection == "cylindrical" and not -math.pi / 2 < lo < hi < math.pi / 2:
            raise ValueError(f"elevation range: a cylindrical panorama cannot reach +-90 "
                             f"degrees, got {math.degrees(lo):g}, {math.degrees(hi):g}")
        W, H = self.size
        if not (isinstance(W, (int, np.integer)) and isinstance(H, (int, np.integer))
                and W >= 2 and H >= 2):
            raise ValueError(f"panorama size: need integers W, H >= 2, got {self.size!r}")

    # -- panorama coordinates <-> directions ---------------------------------------------
    def _height(self, elevation):
        return np.tan(elevation) if self.projection == "cylindrical" else elevation

    def _elevation(self, height):
        return np.arctan(height) if self.projection == "cylindrical" else height

    def directions(self, prow: ArrayLike, pcol: ArrayLike) -> np.ndarray:
        """Unit world directions (..., 3) of panorama pixels (row, col), centres at integers.

        Parameters
        ----------
        prow, pcol : array_like
            Panorama row(s) and column(s), pixel centres at integers (broadcast
            together).
        """
        W, H = self.size
        lo, hi = (self._height(e) for e in self.elevation_range)
        prow, pcol = np.asarray(prow, float), np.asarray(pcol, float)
        if self.up == "away":  # the panorama turned by 180 degrees
            prow, pcol = H - 1 - prow, W - 1 - pcol
        az = np.pi - 2.0 * np.pi * (pcol + 0.5) / W
        el = self._elevation(hi - (prow + 0.5) * (hi - lo) / H)
        return angles_to_directions(az, el)

    def panorama_coords(self, directions: ArrayLike
                       ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Panorama (row, col) of world directions; columns wrap into [−½, W_p − ½).

        Parameters
        ----------
        directions : (..., 3) array_like
            World directions (need not be unit). Rows are not clipped: a direction
            outside the elevation range gets a row outside the panorama.
        """
        W, H = self.size
        lo, hi = (self._height(e) for e in self.elevation_range)
        az, el = directions_to_angles(directions)
        with np.errstate(invalid="ignore"):
            col = np.mod((np.pi - az) * W / (2 * np.pi), W) - 0.5
            row = (hi - self._height(el)) * H / (hi - lo) - 0.5
            if self.up == "away":
                row, col = H - 1 - row, np.mod(W - 1 - col + 0.5, W) - 0.5
        return row, col

    # -- image pixels <-> sensor ---------------------------------------------------------
    @property
    def center_offset_px(self) -> tuple[float, float]:
        """The camera axis's offset from the image centre, ``(drow, dcol)`` px."""
        r0, c0 = optical_center_px(self.image_shape)
        return self.center_px[0] - r0, self.center_px[1] - c0

    def _to_sensor(self, row, col):
        return pixel_to_sensor(row, col, self.image_shape, self.pixel_pitch,
                               center_offset_px=self.center_offset_px)

    def _to_pixel(self, u, v):
        return sensor_to_pixel(u, v, self.image_shape, self.pixel_pitch,
                               center_offset_px=self.center_offset_px)

    # -- the two maps --------------------------------------------------------------------
    def to_image(self, prow: ArrayLike, pcol: ArrayLike
                ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
        """Forward map: image (row, col) seen at panorama pixels (row, col).

        Returns ``(row, col, valid)``; ``valid`` is False (and row, col NaN) where the
        mirror does not show the direction or its image falls outside the frame.

        Parameters
        ----------
        prow, pcol : array_like
            Panorama row(s) and column(s), pixel centres at integers (broadcast
            together).
        """
        d = self.directions(prow, pcol)
        if self.placement.tilt == 0.0:
            u, v, ok = self._symmetric_to_image(d)
        else:
            u, v, ok = direction_to_image(self.placement, d, self.sensor_distance)
        row, col = self._to_pixel(u, v)
        H, W = self.image_shape
        with np.errstate(invalid="ignore"):
            ok = ok & (row >= -0.5) & (row <= H - 0.5) & (col >= -0.5) & (col <= W - 0.5)
        return np.where(ok, row, np.nan), np.where(ok, col, np.nan), ok

    def _symmetric_to_image(self, d):
        """An untilted mirror is rotationally symmetric about the camera axis: the image
        of a direction lies at its azimuth, at a radius set by its elevation alone."""
        az, el = directions_to_angles(d)
        uniq, inv = np.unique(el, return_inverse=True)
        r, _, ok = direction_to_image(self.placement, angles_to_directions(0.0, uniq),
                                      self.sensor_distance)
        r, ok = r[inv].reshape(az.shape), ok[inv].reshape(az.shape)
        return r * np.cos(az), r * np.sin(az), ok

    def from_image(self, row: ArrayLike, col: ArrayLike
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
        """Inverse map: panorama (row, col) of image pixels (row, col).

        Returns ``(prow, pcol, valid)``; ``valid`` is False where the pixel does not see
        the mirror's front or its direction is outside the panorama's elevations.

        Parameters
        ----------
        row, col : array_like
            Image row(s) and column(s), pixel centres at integers (broadcast together).
        """
        u, v = self._to_sensor(row, col)
        d, ok = image_to_direction(self.placement, u, v, self.sensor_distance)
        prow, pcol = self.panorama_coords(d)
        H = self.size[1]
        with np.errstate(invalid="ignore"):
            ok = ok & (prow >= -0.5) & (prow <= H - 0.5)
        return np.where(ok, prow, np.nan), np.where(ok, pcol, np.nan), ok


def _seen_elevations(placement, sensor_distance, shape, pitch, center, n: int = 721):
    """Lowest and highest elevation (rad) that pixels of the frame see on the mirror:
    sampled on the frame's border, on the rim's image and over a grid of the frame."""
    H, W = shape
    pm = PanoramaMap(placement, sensor_distance, (H, W), pitch, center, "equirectangular",
                     (2, 2), (-math.pi / 2, math.pi / 2))
    along_r, along_c = np.linspace(-0.5, H - 0.5, n), np.linspace(-0.5, W - 0.5, n)
    rows = [np.full(n, -0.5), np.full(n, H - 0.5), along_r, along_r]
    cols = [along_c, along_c, np.full(n, -0.5), np.full(n, W - 0.5)]
    gr, gc = np.meshgrid(np.linspace(-0.5, H - 0.5, 129), np.linspace(-0.5, W - 0.5, 129),
                         indexing="ij")
    rows.append(gr.ravel())
    cols.append(gc.ravel())
    # the rim, seen from just inside it
    phi = np.linspace(-np.pi, np.pi, 4 * n, endpoint=False)
    rim = min(placement.rim_radius, placement.profile.max_rho()) * (1 - 1e-7)
    ray = chief_ray(placement, placement.surface(rim * np.cos(phi), rim * np.sin(phi)))
    ru, rv = image_point(ray, sensor_distance)
    rr, rc = pm._to_pixel(ru, rv)
    keep = (ray.cos_incidence > 0) & (rr >= -0.5) & (rr <= H - 0.5) & (rc >= -0.5) & \
        (rc <= W - 0.5)
    rows.append(rr[keep])
    cols.append(rc[keep])
    u, v = pm._to_sensor(np.concatenate(rows), np.concatenate(cols))
    d, ok = image_to_direction(placement, u, v, sensor_distance)
    if not ok.any():
        raise ValueError("no pixel of the image sees the mirror: check the setup, the pixel "
                         "pitch and the mirror's centre")
    _, el = directions_to_angles(d[ok])
    return float(el.min()), float(el.max()), pm, d[ok]


def panorama_map(setup: Setup, image_shape: tuple[int, ...], *, projection: str = "cylindrical",
                 size: tuple[int, int] | None = None,
                 elevation_deg: tuple[float, float] | None = None,
                 pixel_pitch: float | None = None, center_px: tuple[float, float] | None = None,
                 sensor_distance: float | None = None, up: str = "camera") -> PanoramaMap:
    """The panorama of an image of ``setup``: its maps, elevations and size.

    Parameters
    ----------
    setup : mitsweep.config.Setup
    image_shape : (H, W[, C])
        The image's shape (it need not be the setup's resolution).
    projection : {"cylindrical", "equirectangular"}
    size : (W_p, H_p), optional
        Default: columns so that the outermost ring of the mirror's image is sampled at
        one column per pixel of its circumference, rows at the same angular step (at the
        horizon, for cylindrical).
    elevation_deg : (low, high), optional
        Default: from the lowest elevation any pixel of the frame sees on the mirror
        (the whole field of view is kept) to the highest (90° for an untilted mirror,
        the camera's own reflection), capped at :data:`CYLINDRICAL_TOP_DEG` for
        cylindrical panoramas.
    pixel_pitch : float, optional
        mm (default the setup's).
    center_px : (row, col), optional
        Camera axis on the image (default: the setup's calibrated
        ``sensor.center_offset_px`` from the image centre, else the centre).
    sensor_distance : float, optional
        mm (default the setup's reference distance, the grid of its EDOF images).
    up : {"camera", "away"}
        Which way is up in the panorama (:data:`UP_CHOICES`): toward the camera (a
        camera above the mirror, looking down at it) or away from it (a camera below
        the mirror, looking up).

    Returns
    -------
    PanoramaMap
    """
    from .placement import placement_of
    from .reference import reference_geometry

    if projection not in PROJECTIONS:
        raise ValueError(f"projection: must be one of {', '.join(PROJECTIONS)}, got "
                         f"{projection!r}")
    shape = (int(image_shape[0]), int(image_shape[1]))
    pitch = float(setup.sensor.pixel_pitch if pixel_pitch is None else pixel_pitch)
    center = optical_center_px(shape, center_offset_of(setup)) if center_px is None else \
        (float(center_px[0]), float(center_px[1]))
    i = float(reference_geometry(setup).sensor_distance if sensor_distance is None
              else sensor_distance)
    placement = placement_of(setup.mirror)
    lo, hi, pm, seen = _seen_elevations(placement, i, shape, pitch, center)
    if elevation_deg is not None:
        lo, hi = (math.radians(float(e)) for e in elevation_deg)
    elif projection == "cylindrical":
        hi = min(hi, math.radians(CYLINDRICAL_TOP_DEG))
        lo = max(lo, -math.radians(CYLINDRICAL_TOP_DEG))
    if size is None:
        # the outermost ring: the largest image radius (px) about the centre seen
        u, v, _ = direction_to_image(placement, seen[:: max(1, len(seen) // 4000)], i)
        r_px = float(np.nanmax(np.hypot(u, v))) / pitch
        W_p = max(16, int(math.ceil(2 * math.pi * r_px)))
        step = 2 * math.pi / W_p
        span = (math.tan(hi) - math.tan(lo)) if projection == "cylindrical" else hi - lo
        size = (W_p, max(2, int(math.ceil(span / step))))
    size = (int(size[0]), int(size[1]))
    return PanoramaMap(placement, i, shape, pitch, center, projection, size, (lo, hi), up=up)


#: Panorama pixels mapped and resampled at a time by :func:`unwarp`: the maps' work
#: arrays (directions, angles, image coordinates, about 200 bytes a pixel) stay ~50 MiB
#: whatever the panorama's size.
UNWARP_BLOCK_PIXELS = 1 << 18
#: Bytes a block's pixel needs while it is mapped and resampled (measured: ~150).
_BLOCK_BYTES_PER_PIXEL = 256


#: Rows of edge values around the image before its spline prefilter, as
#: ``scipy.ndimage.map_coordinates`` pads for ``mode="nearest"`` (so results match it).
_SPLINE_PAD = 12


def panorama_bytes(size: tuple[int, int], image_shape: tuple[int, ...], channels: int,
                   itemsize: int) -> float:
    """Peak memory of :func:`unwarp`, bytes: the panorama (``channels`` samples of
    ``itemsize`` bytes a pixel) and its validity mask, the image's spline coefficients
    (float64, padded) and one block's work.

    A float (sizes from the command line can exceed any integer type NumPy uses).

    Parameters
    ----------
    size : (int, int)
        Panorama columns and rows, ``(W_p, H_p)``.
    image_shape : tuple of int
        Shape of the image unwarped, ``(H, W[, C])`` (only ``H, W`` are used).
    channels : int
        Samples per pixel (1 for an (H, W) image).
    itemsize : int
        Bytes per sample of the panorama (4 for float32).
    """
    W_p, H_p = (float(n) for n in size)
    H, W = (float(n) + 2 * _SPLINE_PAD for n in image_shape[:2])
    block = min(W_p * H_p, float(max(UNWARP_BLOCK_PIXELS, W_p)))
    return (W_p * H_p * (channels * itemsize + 1) + H * W * 8 * (channels + 1)
            + block * _BLOCK_BYTES_PER_PIXEL)


def unwarp(image: np.ndarray, pmap: PanoramaMap, *,
           order: int = 3) -> tuple[np.ndarray, NDArray[np.bool_]]:
    """Resample ``image`` onto the panorama of ``pmap``.

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
        Linear values; float32 stays float32.
    pmap : PanoramaMap
    order : int
        Spline order of the resampling (3: cubic).

    Returns
    -------
    panorama : (H_p, W_p[, C]) ndarray
        0 where the image does not show the direction.
    valid : (H_p, W_p) bool ndarray

    Raises
    ------
    mitsweep.resources.ResourceError
        The panorama would not fit the memory (:func:`panorama_bytes`); checked before
        it is made.

    Notes
    -----
    The panorama is mapped and resampled in blocks of rows
    (:data:`UNWARP_BLOCK_PIXELS` pixels), so that the maps' work arrays do not grow with
    the panorama.
    """
    from scipy.ndimage import map_coordinates, spline_filter

    from ..resources import check_allocation

    img = np.asarray(image)
    if img.shape[:2] != tuple(pmap.image_shape):
        raise ValueError(f"image is {img.shape[1]}x{img.shape[0]}, the panorama map was made "
                         f"for {pmap.image_shape[1]}x{pmap.image_shape[0]}")
    dtype = img.dtype if np.issubdtype(img.dtype, np.floating) else np.float64
    W_p, H_p = pmap.size
    chans = img[..., None] if img.ndim == 2 else img
    C = chans.shape[2]
    check_allocation(f"panorama {W_p}x{H_p}",
                     panorama_bytes(pmap.size, img.shape, C, np.dtype(dtype).itemsize))
    # each channel's spline coefficients once (map_coordinates would filter the whole
    # image again for every block), padded with edge values as map_coordinates pads them
    planes = []
    for c in range(C):
        padded = np.pad(chans[..., c].astype(np.float64), _SPLINE_PAD, mode="edge")
        planes.append(spline_filter(padded, order, mode="nearest") if order > 1 else padded)
        del padded
    out = np.zeros((H_p, W_p, C), dtype)
    valid = np.zeros((H_p, W_p), bool)
    rows = max(1, UNWARP_BLOCK_PIXELS // W_p)
    for r0 in range(0, H_p, rows):
        pr, pc = np.meshgrid(np.arange(r0, min(H_p, r0 + rows)), np.arange(W_p),
                             indexing="ij")
        row, col, ok = pmap.to_image(pr, pc)
        coords = np.stack([np.where(ok, row, 0.0), np.where(ok, col, 0.0)]) + _SPLINE_PAD
        del row, col
        for c in range(C):
            out[r0:r0 + rows, :, c] = map_coordinates(planes[c], coords, order=order,
                                                      mode="nearest", prefilter=False)
        out[r0:r0 + rows][~ok] = 0
        valid[r0:r0 + rows] = ok
    return (out[..., 0] if img.ndim == 2 else out), valid
