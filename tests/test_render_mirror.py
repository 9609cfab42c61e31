"""Mirror meshes: error bounds, orientation, disk cache; analytic sphere selection."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mitsweep.config import Mirror
from mitsweep.optics import Profile, profile_of
from mitsweep.render.mirror import (cached_mesh_file, mesh_errors, tessellate,
                                    uses_analytic_sphere)

PROFILES = {
    "sphere": (Profile(25.0, 0.0), 25.0),
    "paraboloid": (Profile(28.2, -1.0), 28.25),
    "hyperboloid": (Profile(20.0, -2.5), 30.0),
    "asphere": (Profile(30.0, -1.0, (2e-6, -1e-9)), 25.0),
}


@pytest.mark.parametrize("name", sorted(PROFILES))
@pytest.mark.parametrize("tol", [1e-2, 2e-3])
def test_tessellation_meets_both_error_bounds(name, tol):
    profile, rim = PROFILES[name]
    mesh = tessellate(profile, rim, sag_tol=tol, normal_tol=tol)
    assert mesh.sag_error <= tol and mesh.normal_error <= tol
    # Re-measure independently of the stored numbers.
    es, en = mesh_errors(profile, mesh.positions, mesh.normals, mesh.faces)
    assert es <= tol and en <= tol
    # Vertices lie on the profile (float64 here): z = −s(ρ).
    rho = np.hypot(mesh.positions[:, 0], mesh.positions[:, 1])
    np.testing.assert_allclose(mesh.positions[:, 2], -profile.sag(rho), atol=1e-9)


@pytest.mark.parametrize("name", sorted(PROFILES))
def test_mesh_faces_and_normals_face_the_camera(name):
    profile, rim = PROFILES[name]
    mesh = tessellate(profile, rim, sag_tol=1e-2, normal_tol=1e-2)
    p = mesh.positions[mesh.faces]
    face_n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    vert_n = mesh.normals[mesh.faces].mean(axis=1)
    # Counter-clockwise from +z: geometric and shading normals agree (Mitsuba's
    # conductor reflects only on the side the shading frame faces).
    assert np.all(np.sum(face_n * vert_n, axis=-1) > 0)
    assert np.all(mesh.normals[:, 2] >= -1e-12)
    np.testing.assert_allclose(np.linalg.norm(mesh.normals, axis=-1), 1.0, atol=1e-12)


def test_finer_bound_means_more_triangles_and_smaller_error():
    profile, rim = PROFILES["paraboloid"]
    coarse = tessellate(profile, rim, sag_tol=1e-2, normal_tol=1e-2)
    fine = tessellate(profile, rim, sag_tol=1e-3, normal_tol=1e-3)
    assert fine.n_triangles > coarse.n_triangles
    assert fine.sag_error < coarse.sag_error and fine.normal_error < coarse.normal_error


def test_bad_bounds_raise():
    profile, rim = PROFILES["sphere"]
    with pytest.raises(ValueError, match="sag_tol"):
        tessellate(profile, rim, sag_tol=0.0)
    with pytest.raises(ValueError, match="triangles"):
        tessellate(profile, rim, sag_tol=1e-9, normal_tol=1e-9)


def test_mesh_is_cached_on_disk_under_mitsweep_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("MITSWEEP_CACHE", str(tmp_path))
    m = Mirror(kind="paraboloid", radius=28.2, conic=-1.0, rim_radius=28.25,
               vertex_distance=352.0)
    path, stats = cached_mesh_file(m, sag_tol=5e-3, normal_tol=5e-3)
    assert path.parent == tmp_path / "meshes" and path.is_file()
    assert path.read_bytes().startswith(b"ply\nformat binary_little_endian")
    mtime = path.stat().st_mtime_ns
    path2, stats2 = cached_mesh_file(m, sag_tol=5e-3, normal_tol=5e-3)
    assert path2 == path and path.stat().st_mtime_ns == mtime and stats2 == stats
    other, _ = cached_mesh_file(m, sag_tol=4e-3, normal_tol=5e-3)
    assert other != path
    assert json.loads(path.with_suffix(".json").read_text())["triangles"] == stats["triangles"]


def test_ply_loads_in_mitsuba_with_the_same_geometry(tmp_path, monkeypatch):
    import mitsuba as mi

    from mitsweep.render.sensor import register

    register()
    monkeypatch.setenv("MITSWEEP_CACHE", str(tmp_path))
    m = Mirror(kind="conic", radius=20.0, conic=-2.5, rim_radius=30.0, vertex_distance=300.0)
    path, stats = cached_mesh_file(m, sag_tol=5e-3, normal_tol=5e-3)
    shape = mi.load_dict({"type": "ply", "filename": str(path), "face_normals": False})
    assert shape.face_count() == stats["triangles"]
    pos = np.array(mi.traverse(shape)["vertex_positions"]).reshape(-1, 3)
    rho = np.hypot(pos[:, 0], pos[:, 1])
    # float32 storage: ~1e-6 relative on coordinates of tens of mm.
    np.testing.assert_allclose(pos[:, 2], -profile_of(m).sag(rho), atol=5e-5)


@pytest.mark.parametrize("kind, rim, expected", [
    ("sphere", 25.0, True), ("sphere", 20.0, False), ("paraboloid", 28.25, False)])
def test_analytic_sphere_only_for_a_full_hemisphere(kind, rim, expected):
    if kind == "sphere":
        m = Mirror(kind="sphere", radius=25.0, rim_radius=rim, vertex_distance=327.0)
    else:
        m = Mirror(kind="paraboloid", radius=28.2, conic=-1.0, rim_radius=rim,
                   vertex_distance=352.0)
    assert uses_analytic_sphere(m) is expected
