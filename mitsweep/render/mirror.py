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
rad at the same points. Meshes are cached as PLY under ``$MITSWEEP_CACHE`` (default
``~/.cache/mitsweep``)/``meshes``, keyed by the profile and both bounds.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..io.cache import cache_root
from ..optics import Profile, placement_of, profile_of

__all__ = ["MirrorMesh", "tessellate", "mesh_errors", "mirror_shape",
           "uses_analytic_sphere", "DEFAULT_SAG_TOL", "DEFAULT_NORMAL_TOL"]

logger = logging.getLogger(__name__)

#: Default bounds: 0.1 µm sag and 0.1 mrad normal error (a pixel's chief-ray bundle
#: covers ~0.1 mm of the paper's mirrors, where the normal turns by ~8 mrad).
DEFAULT_SAG_TOL = 1e-4
DEFAULT_NORMAL_TOL = 1e-4
#: Mesh errors are measured where the surface normal is within this angle of the axis.
GRAZING_LIMIT_DEG = 75.0
_MAX_TRIANGLES = 8_000_000
_MESH_VERSION = 1


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


def mesh_errors(profile: Profile, positions, normals, faces, *,
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


def uses_analytic_sphere(mirror) -> bool:
    """True where Mitsuba's exact ``sphere`` is the mirror (a full hemisphere)."""
    return mirror.is_sphere and mirror.rim_radius >= mirror.radius * (1 - 1e-12)


def _cache_key(profile: Profile, rim: float, sag_tol: float, normal_tol: float) -> str:
    blob = json.dumps({"R": profile.radius, "k": profile.conic, "a": list(profile.aspheric),
                       "rim": rim, "sag_tol": sag_tol, "normal_tol": normal_tol,
                       "v": _MESH_VERSION}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:20]


def _write_ply(path: Path, mesh: MirrorMesh) -> None:
    """Binary little-endian PLY with normals, written atomically."""
    from ..io import atomic_path

    v = np.concatenate([mesh.positions, mesh.normals], axis=-1).astype("<f4")
    f = np.empty(mesh.faces.shape[0], dtype=[("n", "u1"), ("i", "<u4", (3,))])
    f["n"] = 3
    f["i"] = mesh.faces
    header = (f"ply\nformat binary_little_endian 1.0\n"
              f"comment mitsweep mirror rings={mesh.n_rings} segments={mesh.n_segments} "
              f"sag_error={mesh.sag_error:.6g} normal_error={mesh.normal_error:.6g}\n"
              f"element vertex {v.shape[0]}\nproperty float x\nproperty float y\n"
              f"property float z\nproperty float nx\nproperty float ny\nproperty float nz\n"
              f"element face {f.shape[0]}\nproperty list uchar uint vertex_indices\n"
              f"end_header\n").encode()
    with atomic_path(path, suffix=".ply") as tmp:
        with open(tmp, "wb") as fh:
            fh.write(header)
            fh.write(v.tobytes())
            fh.write(f.tobytes())


def cached_mesh_file(mirror, *, sag_tol: float = DEFAULT_SAG_TOL,
                     normal_tol: float = DEFAULT_NORMAL_TOL) -> tuple[Path, dict]:
    """The PLY file of the mirror's mesh (built and cached on first use) and its stats."""
    profile = profile_of(mirror)
    key = _cache_key(profile, mirror.rim_radius, sag_tol, normal_tol)
    folder = cache_root() / "meshes"
    path = folder / f"mirror-{key}.ply"
    meta_path = folder / f"mirror-{key}.json"
    if path.is_file() and meta_path.is_file():
        try:
            return path, json.loads(meta_path.read_text())
        except ValueError:
            logger.warning("mesh cache %s: unreadable stats, rebuilding", meta_path)
    folder.mkdir(parents=True, exist_ok=True)
    mesh = tessellate(profile, mirror.rim_radius, sag_tol=sag_tol, normal_tol=normal_tol)
    _write_ply(path, mesh)
    stats = {"triangles": mesh.n_triangles, "rings": mesh.n_rings,
             "segments": mesh.n_segments, "sag_error_mm": mesh.sag_error,
             "normal_error_rad": mesh.normal_error, "sag_tol_mm": sag_tol,
             "normal_tol_rad": normal_tol}
    from ..io import write_text_atomic

    write_text_atomic(meta_path, json.dumps(stats))
    logger.info("mirror mesh %s: %d triangles (sag %.2g mm, normal %.2g rad)", path.name,
             mesh.n_triangles, mesh.sag_error, mesh.normal_error)
    return path, stats


def mirror_shape(mirror, *, force_mesh: bool = False, sag_tol: float = DEFAULT_SAG_TOL,
                 normal_tol: float = DEFAULT_NORMAL_TOL) -> tuple[dict, dict]:
    """A Mitsuba shape dict for the mirror (perfect conductor) and a description.

    Returns
    -------
    shape : dict
        For :func:`mitsuba.load_dict` (world frame, mm).
    info : dict
        ``{"kind": "sphere"|"mesh", ...}`` with the mesh statistics.
    """
    import mitsuba as mi

    bsdf = {"type": "conductor", "material": "none"}  # perfect mirror, reflectance 1
    placement = placement_of(mirror)
    rot = placement.rotation
    if uses_analytic_sphere(mirror) and not force_mesh:
        centre = rot @ np.array([0.0, 0.0, -mirror.radius])
        return ({"type": "sphere", "center": centre.tolist(), "radius": mirror.radius,
                 "bsdf": bsdf}, {"kind": "sphere"})
    path, stats = cached_mesh_file(mirror, sag_tol=sag_tol, normal_tol=normal_tol)
    m = np.eye(4)
    m[:3, :3] = rot
    shape = {"type": "ply", "filename": str(path), "face_normals": False,
             "to_world": mi.ScalarTransform4f(m.tolist()), "bsdf": bsdf}
    return shape, {"kind": "mesh", **stats}
