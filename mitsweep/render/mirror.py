"""Mirror geometry for Mitsuba: the analytic sphere, or an error-bounded mesh.

A spherical mirror whose rim is its full hemisphere is Mitsuba's analytic ``sphere``
(exact, and cheaper than any mesh). Every other profile (conic, even asphere, or a
sphere cut at a smaller rim) becomes a triangle mesh built from the same
:class:`mitsweep.optics.Profile` the optics use, with analytic vertex normals, in the
mirror's local frame (vertex at the origin, convex toward +z), placed by the tilt
rotation of :func:`mitsweep.optics.placement_of`.

Tessellation (:func:`tessellate`): a polar grid, rings uniform in arc length along the
profile, the same number of vertices on every ring. Starting from the chord estimate
``κ h² / 8 ≤ sag_tol``, the grid is refined (×1.4 per direction) until the *measured*
errors satisfy both bounds: the sag error (distance along the normal from the flat
triangle to the surface, at edge midpoints and centroids) ``≤ sag_tol`` mm and the
angle between the interpolated shading normal and the true normal ``≤ normal_tol``
rad at the same points. The mesh reaches Mitsuba as an in-memory ``mi.Mesh`` built from
the arrays (:func:`mirror_shape`; no file is written for it). The arrays are cached
(NumPy ``.npz``) under :func:`mitsweep.io.cache.cache_root`/``meshes``, keyed by the
profile, the rim and both bounds, unless ``MITSWEEP_CACHE=0`` (or ``cache=False``); an
unusable cache folder costs one warning and the mesh is built in memory
(:func:`mitsweep.io.cache.cache_dir`).
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..config import Mirror, Setup
from ..io.cache import cache_dir, cache_enabled, cache_root, warn_unusable
from ..optics import Profile, placement_of, profile_of

__all__ = ["MirrorMesh", "tessellate", "mesh_errors", "mirror_mesh", "mirror_shape",
           "cache_enabled", "uses_analytic_sphere", "DEFAULT_SAG_TOL", "DEFAULT_NORMAL_TOL"]

logger = logging.getLogger(__name__)

#: Default bounds: 0.1 µm sag and 0.1 mrad normal error (a pixel's chief-ray bundle
#: covers ~0.1 mm of the paper's mirrors, where the normal turns by ~8 mrad).
DEFAULT_SAG_TOL = 1e-4
DEFAULT_NORMAL_TOL = 1e-4
#: Mesh errors are measured where the surface normal is within this angle of the axis.
GRAZING_LIMIT_DEG = 75.0
_MAX_TRIANGLES = 8_000_000
_MESH_VERSION = 2  # 2: cached as .npz arrays (was PLY)


@dataclass(frozen=True)
class MirrorMesh:
    """A tessellated mirror in its local frame.

    Attributes
    ----------
    positions, normals : (V, 3) ndarray
        Vertex positions (mm) and unit outward normals.
    faces : (F, 3) ndarray of uint32
        Counter-clockwise seen from +z (the camera side), so face normals face out.
    n_rings, n_segments : int
        Radial rings and vertices per ring.
    sag_error, normal_error : float
        Measured maxima (mm, rad), see :func:`mesh_errors`.
    """

    positions: np.ndarray
    normals: np.ndarray
    faces: np.ndarray
    n_rings: int
    n_segments: int
    sag_error: float
    normal_error: float

    @property
    def n_triangles(self) -> int:
        return int(self.faces.shape[0])


def _arc_length(profile: Profile, rim: float) -> tuple[np.ndarray, np.ndarray]:
    """(ρ, cumulative profile arc length from the axis), both mm, on a dense grid."""
    # ρ = rim sin φ keeps the arc-length integrand finite at a hemisphere's rim.
    phi = np.linspace(0.0, 0.5 * math.pi, 20001)
    rho = rim * np.sin(phi)
    z = profile.sag(rho)
    seg = np.hypot(np.diff(rho), np.diff(z))
    return rho, np.concatenate([[0.0], np.cumsum(seg)])


def _ring_radii(profile: Profile, rim: float, n_rings: int) -> np.ndarray:
    """ρ of ``n_rings`` rings (plus the centre, 0) uniform in profile arc length."""
    rho, s = _arc_length(profile, rim)
    targets = np.linspace(0.0, s[-1], n_rings + 1)
    out = np.interp(targets, s, rho)
    out[-1] = rim
    return out


def _grid(profile: Profile, rim: float, n_rings: int, n_segments: int):
    radii = _ring_radii(profile, rim, n_rings)[1:]
    ang = np.arange(n_segments) * (2.0 * math.pi / n_segments)
    rr, aa = np.meshgrid(radii, ang, indexing="ij")
    x = np.concatenate([[0.0], (rr * np.cos(aa)).ravel()])
    y = np.concatenate([[0.0], (rr * np.sin(aa)).ravel()])
    rho = np.hypot(x, y)
    z = -profile.sag(rho)
    nr, nz = profile.normal_components(rho)
    safe = np.where(rho > 0, rho, 1.0)
    nx, ny = nr * x / safe, nr * y / safe
    positions = np.stack([x, y, z], axis=-1)
    normals = np.stack([nx, ny, nz], axis=-1)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    faces = []
    m = n_segments
    j = np.arange(m)
    jn = (j + 1) % m
    faces.append(np.stack([np.zeros(m, int), 1 + j, 1 + jn], axis=-1))  # centre fan
    for r in range(n_rings - 1):
        a, b = 1 + r * m + j, 1 + r * m + jn
        c, d = 1 + (r + 1) * m + j, 1 + (r + 1) * m + jn
        faces.append(np.stack([a, c, d], axis=-1))
        faces.append(np.stack([a, d, b], axis=-1))
    return positions, normals, np.concatenate(faces).astype(np.uint32)


def mesh_errors(profile: Profile, positions: NDArray[np.floating],
                normals: NDArray[np.floating], faces: NDArray[np.integer], *,
                max_normal_angle_deg: float = GRAZING_LIMIT_DEG) -> tuple[float, float]:
    """Measured (sag error mm, normal error rad) of a mesh against its profile.

    Evaluated at every face's centroid and edge midpoints: the sag error is the axial
    gap between the flat triangle and the surface times the normal's z component (the
    distance along the normal, to first order); the normal error is the angle between
    the barycentric interpolation of the vertex normals (as Mitsuba shades) and the
    true normal at the same (x, y) — the point a ray arriving along the axis (the
    camera's rays, within a few degrees) hits. Points where the true normal is more
    than ``max_normal_angle_deg`` from the axis (seen at grazing incidence, outside
    every FOV zone; the rim of a hemisphere) are left out.

    Parameters
    ----------
    profile : Profile
        The surface the mesh approximates (its sag and normal, mm).
    positions : (V, 3) ndarray
        Vertex positions in the mirror's local frame, mm.
    normals : (V, 3) ndarray
        Unit shading normals at the vertices.
    faces : (F, 3) ndarray of int
        Vertex indices of each triangle.
    max_normal_angle_deg : float, optional
        Points whose true normal is further than this from the axis are not measured,
        degrees (default :data:`GRAZING_LIMIT_DEG`, 75).
    """
    p = positions[faces]          # (F, 3, 3)
    n = normals[faces]
    bary = np.array([[1 / 3, 1 / 3, 1 / 3], [0.5, 0.5, 0.0], [0.0, 0.5, 0.5], [0.5, 0.0, 0.5]])
    sag_err = 0.0
    nrm_err = 0.0
    for w in bary:
        q = np.einsum("k,fkc->fc", w, p)
        ni = np.einsum("k,fkc->fc", w, n)
        ni /= np.linalg.norm(ni, axis=-1, keepdims=True)
        rho = np.hypot(q[:, 0], q[:, 1])
        nr, nz = profile.normal_components(rho)
        safe = np.where(rho > 0, rho, 1.0)
        nt = np.stack([nr * q[:, 0] / safe, nr * q[:, 1] / safe, nz], axis=-1)
        keep = nz >= math.cos(math.radians(max_normal_angle_deg))
        if not keep.any():
            continue
        gap = np.abs(q[keep, 2] + profile.sag(rho[keep])) * nz[keep]
        sag_err = max(sag_err, float(np.max(gap)))
        cosang = np.clip(np.sum(ni[keep] * nt[keep], axis=-1), -1.0, 1.0)
        nrm_err = max(nrm_err, float(np.max(np.arccos(cosang))))
    return sag_err, nrm_err


def tessellate(profile: Profile, rim_radius: float, *, sag_tol: float = DEFAULT_SAG_TOL,
               normal_tol: float = DEFAULT_NORMAL_TOL) -> MirrorMesh:
    """The coarsest polar mesh (in this family) within both error bounds.

    Parameters
    ----------
    profile : Profile
    rim_radius : float
        Radial extent, mm.
    sag_tol : float
        Largest allowed distance from a triangle to the surface, mm (> 0).
    normal_tol : float
        Largest allowed shading-normal error, rad (> 0).

    Raises
    ------
    ValueError
        For non-positive bounds, or bounds needing more than 8 M triangles.
    """
    if not (sag_tol > 0 and normal_tol > 0):
        raise ValueError(f"mesh: sag_tol and normal_tol must be > 0, got {sag_tol}, {normal_tol}")
    rho = np.linspace(0.0, rim_radius * (1 - 1e-9), 512)
    kappa = float(np.max(1.0 / np.minimum(*profile.principal_radii(rho))))
    arc = float(_arc_length(profile, rim_radius)[1][-1])
    h = math.sqrt(8.0 * sag_tol / kappa)
    n_rings = max(2, math.ceil(arc / h))
    n_segments = max(8, math.ceil(2.0 * math.pi * rim_radius / h))
    while True:
        if 2 * n_rings * n_segments > _MAX_TRIANGLES:
            raise ValueError(f"mesh: sag_tol={sag_tol:g} mm and normal_tol={normal_tol:g} rad "
                             f"need more than {_MAX_TRIANGLES} triangles; loosen them")
        pos, nrm, faces = _grid(profile, rim_radius, n_rings, n_segments)
        es, en = mesh_errors(profile, pos, nrm, faces)
        if es <= sag_tol and en <= normal_tol:
            return MirrorMesh(pos, nrm, faces, n_rings, n_segments, es, en)
        grow = 1.4 if max(es / sag_tol, en / normal_tol) < 4 else 2.0
        n_rings = math.ceil(n_rings * grow)
        n_segments = math.ceil(n_segments * grow)


def uses_analytic_sphere(mirror: Mirror) -> bool:
    """True where Mitsuba's exact ``sphere`` is the mirror (a full hemisphere).

    Parameters
    ----------
    mirror : Mirror
        A spherical mirror whose rim radius reaches its radius is a hemisphere; any
        other profile or a smaller rim is meshed.
    """
    return mirror.is_sphere and mirror.rim_radius >= mirror.radius * (1 - 1e-12)


def _cache_key(profile: Profile, rim: float, sag_tol: float, normal_tol: float) -> str:
    blob = json.dumps({"R": profile.radius, "k": profile.conic, "a": list(profile.aspheric),
                       "rim": rim, "sag_tol": sag_tol, "normal_tol": normal_tol,
                       "v": _MESH_VERSION}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:20]


def _read_cached(path: Path) -> tuple[MirrorMesh, dict] | None:
    try:
        with np.load(path) as z:
            stats = json.loads(str(z["stats"]))
            mesh = MirrorMesh(z["positions"], z["normals"], z["faces"], stats["rings"],
                              stats["segments"], stats["sag_error_mm"], stats["normal_error_rad"])
        return mesh, stats
    except (OSError, ValueError, KeyError) as exc:
        logger.warning("mesh cache %s: unreadable (%s), rebuilding", path, exc)
        return None


def _write_cached(path: Path, mesh: MirrorMesh, stats: dict) -> None:
    from ..io import atomic_path

    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path, suffix=".npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, positions=mesh.positions, normals=mesh.normals, faces=mesh.faces,
                     stats=json.dumps(stats))


def mirror_mesh(mirror: Mirror, *, sag_tol: float = DEFAULT_SAG_TOL,
                normal_tol: float = DEFAULT_NORMAL_TOL,
                cache: bool | None = None) -> tuple[MirrorMesh, dict]:
    """The mirror's mesh within both bounds (:func:`tessellate`) and its statistics.

    ``cache`` (default :func:`cache_enabled`) keeps the arrays in
    ``cache_root()/meshes/mirror-KEY.npz``, keyed by the profile, the rim and both
    bounds: a fine mesh takes seconds to build and milliseconds to read.

    Parameters
    ----------
    mirror : Mirror
        The mirror: its profile and rim radius (mm).
    sag_tol : float, optional
        Largest allowed distance from a triangle to the surface, mm (> 0).
    normal_tol : float, optional
        Largest allowed shading-normal error, rad (> 0).
    cache : bool, optional
        Read and write the mesh cache (default None: :func:`cache_enabled`); a cache
        folder that cannot be used is warned about and skipped.

    Returns
    -------
    mesh : MirrorMesh
        In the mirror's local frame.
    stats : dict
        ``triangles``, ``rings``, ``segments``, ``sag_error_mm``, ``normal_error_rad``
        (measured, :func:`mesh_errors`), ``sag_tol_mm``, ``normal_tol_rad``.
    """
    profile = profile_of(mirror)
    use_cache = cache_enabled() if cache is None else bool(cache)
    folder = cache_dir("meshes") if use_cache else None  # None: unusable (warned)
    path = None if folder is None else folder / _cache_name(mirror, sag_tol, normal_tol)
    if path is not None and path.is_file():
        hit = _read_cached(path)
        if hit is not None:
            return hit
    mesh = tessellate(profile, mirror.rim_radius, sag_tol=sag_tol, normal_tol=normal_tol)
    stats = {"triangles": mesh.n_triangles, "rings": mesh.n_rings,
             "segments": mesh.n_segments, "sag_error_mm": mesh.sag_error,
             "normal_error_rad": mesh.normal_error, "sag_tol_mm": sag_tol,
             "normal_tol_rad": normal_tol}
    logger.info("mirror mesh: %d triangles (sag %.2g mm, normal %.2g rad)%s",
                mesh.n_triangles, mesh.sag_error, mesh.normal_error,
                f", cached as {path}" if path is not None else "")
    if path is not None:
        try:
            _write_cached(path, mesh, stats)
        except OSError as exc:  # a full disk, a folder gone meanwhile: the mesh is here
            warn_unusable(path.parent, exc)
    return mesh, stats


def cache_file(mirror: Mirror, *, sag_tol: float = DEFAULT_SAG_TOL,
               normal_tol: float = DEFAULT_NORMAL_TOL) -> Path:
    """Where :func:`mirror_mesh` caches this mesh (it may not exist).

    Parameters
    ----------
    mirror : Mirror
        The mirror: its profile and rim radius (mm).
    sag_tol : float, optional
        The mesh's sag bound, mm: part of the cache key.
    normal_tol : float, optional
        The mesh's normal bound, rad: part of the cache key.
    """
    return cache_root() / "meshes" / _cache_name(mirror, sag_tol, normal_tol)


def _cache_name(mirror: Mirror, sag_tol: float, normal_tol: float) -> str:
    key = _cache_key(profile_of(mirror), mirror.rim_radius, sag_tol, normal_tol)
    return f"mirror-{key}.npz"


def cached_mesh_file(mirror: Mirror, *, sag_tol: float = DEFAULT_SAG_TOL,
                     normal_tol: float = DEFAULT_NORMAL_TOL) -> tuple[Path, dict]:
    """The cache file of the mirror's mesh (built and cached on first use; absent where
    the cache is unusable) and its stats.

    Parameters
    ----------
    mirror : Mirror
        The mirror: its profile and rim radius (mm).
    sag_tol : float, optional
        Largest allowed distance from a triangle to the surface, mm (> 0).
    normal_tol : float, optional
        Largest allowed shading-normal error, rad (> 0).
    """
    _, stats = mirror_mesh(mirror, sag_tol=sag_tol, normal_tol=normal_tol, cache=True)
    return cache_file(mirror, sag_tol=sag_tol, normal_tol=normal_tol), stats


def _mitsuba_mesh(mesh: MirrorMesh, rotation, bsdf: dict):
    """An in-memory ``mi.Mesh`` of ``mesh`` rotated into the world frame (no file)."""
    import drjit as dr
    import mitsuba as mi

    props = mi.Properties()
    props["bsdf"] = mi.load_dict(bsdf)
    out = mi.Mesh("mirror", mesh.positions.shape[0], mesh.faces.shape[0], props=props,
                  has_vertex_normals=True)
    # Rotated in float64, stored in float32 as Mitsuba keeps vertices.
    pos = (mesh.positions @ np.asarray(rotation).T).astype(np.float32)
    nrm = (mesh.normals @ np.asarray(rotation).T).astype(np.float32)
    params = mi.traverse(out)
    params["vertex_positions"] = dr.ravel(mi.Point3f(pos[:, 0], pos[:, 1], pos[:, 2]))
    params["vertex_normals"] = dr.ravel(mi.Vector3f(nrm[:, 0], nrm[:, 1], nrm[:, 2]))
    params["faces"] = mi.UInt32(mesh.faces.astype(np.uint32).ravel())
    params.update()
    return out


def mirror_shape(mirror: Setup | Mirror, *, force_mesh: bool = False,
                 sag_tol: float | None = None, normal_tol: float | None = None,
                 cache: bool | None = None) -> tuple[Any, dict]:
    """The setup's mirror as a Mitsuba shape (a perfect conductor), for any scene.

    Parameters
    ----------
    mirror : mitsweep.config.Setup or mitsweep.config.Mirror
        A setup (its mirror, and its ``scene.mesh_sag_tol``/``mesh_normal_tol`` as the
        default bounds) or a mirror section.
    force_mesh : bool
        Mesh the mirror even where the analytic sphere is exact (accuracy studies).
    sag_tol, normal_tol : float, optional
        Mesh bounds, mm and rad (default: the setup's, else :data:`DEFAULT_SAG_TOL`
        and :data:`DEFAULT_NORMAL_TOL`).
    cache : bool, optional
        Keep the mesh's arrays in the disk cache (:func:`mirror_mesh`; default
        :func:`cache_enabled`). Off, the mesh is built in memory every call.

    Returns
    -------
    shape : dict or mitsuba.Mesh
        A value for :func:`mitsuba.load_dict` in the mirror's world frame (mm: vertex at
        the origin, axis +z toward the camera at ``(0, 0, vertex_distance)``): the
        analytic ``sphere`` dict where it is exact (a full hemisphere), else an
        in-memory ``mi.Mesh`` with analytic vertex normals.
    info : dict
        ``kind`` (``"sphere"`` or ``"mesh"``), ``sag_error_mm`` and ``normal_error_rad``
        (the measured bounds; 0 for the sphere) and, for a mesh, its statistics.

    Examples
    --------
    >>> shape, info = mirror_shape(setup)                       # doctest: +SKIP
    >>> scene = mi.load_dict({"type": "scene", "mirror": shape,
    ...                       "sensor": camera_dict(setup, sensor_distance=52.0),
    ...                       "world": {"type": "constant"}})     # doctest: +SKIP
    """
    sc = getattr(mirror, "scene", None)
    if hasattr(mirror, "mirror"):
        mirror = mirror.mirror
    if sag_tol is None:
        sag_tol = sc.mesh_sag_tol if sc is not None else DEFAULT_SAG_TOL
    if normal_tol is None:
        normal_tol = sc.mesh_normal_tol if sc is not None else DEFAULT_NORMAL_TOL
    bsdf = {"type": "conductor", "material": "none"}  # perfect mirror, reflectance 1
    rot = placement_of(mirror).rotation
    if uses_analytic_sphere(mirror) and not force_mesh:
        centre = rot @ np.array([0.0, 0.0, -mirror.radius])
        return ({"type": "sphere", "center": centre.tolist(), "radius": mirror.radius,
                 "bsdf": bsdf}, {"kind": "sphere", "sag_error_mm": 0.0, "normal_error_rad": 0.0})
    mesh, stats = mirror_mesh(mirror, sag_tol=sag_tol, normal_tol=normal_tol, cache=cache)
    return _mitsuba_mesh(mesh, rot, bsdf), {"kind": "mesh", **stats}
