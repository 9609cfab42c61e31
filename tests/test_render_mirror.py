"""Mirror meshes: error bounds, orientation, in-memory Mitsuba meshes, the optional disk
cache; analytic sphere selection; the mirror as a part of any scene."""

from __future__ import annotations

import numpy as np
import pytest

from mitsweep.config import Mirror
from mitsweep.optics import Profile, profile_of
from mitsweep.render.mirror import (cache_enabled, cached_mesh_file, mesh_errors, mirror_mesh,
                                    mirror_shape, tessellate, uses_analytic_sphere)

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
    assert path.parent == tmp_path / "meshes" and path.is_file() and path.suffix == ".npz"
    mtime = path.stat().st_mtime_ns
    path2, stats2 = cached_mesh_file(m, sag_tol=5e-3, normal_tol=5e-3)
    assert path2 == path and path.stat().st_mtime_ns == mtime and stats2 == stats
    other, _ = cached_mesh_file(m, sag_tol=4e-3, normal_tol=5e-3)
    assert other != path
    cached, _ = mirror_mesh(m, sag_tol=5e-3, normal_tol=5e-3)
    fresh, fresh_stats = mirror_mesh(m, sag_tol=5e-3, normal_tol=5e-3, cache=False)
    np.testing.assert_array_equal(cached.positions, fresh.positions)
    np.testing.assert_array_equal(cached.faces, fresh.faces)
    assert fresh_stats == stats


@pytest.mark.parametrize("off", ["0", "off"])
def test_cache_off_writes_nothing(tmp_path, monkeypatch, off):
    monkeypatch.setenv("MITSWEEP_CACHE", off)
    monkeypatch.chdir(tmp_path)
    assert not cache_enabled()
    m = Mirror(kind="conic", radius=20.0, conic=-2.5, rim_radius=30.0, vertex_distance=300.0)
    _, stats = mirror_mesh(m, sag_tol=5e-3, normal_tol=5e-3)
    assert stats["sag_error_mm"] <= 5e-3 and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("tilt", [0.0, 20.0])
def test_mirror_shape_is_an_in_memory_mesh_on_the_profile(tmp_path, monkeypatch, tilt):
    """The mesh reaches Mitsuba from arrays (no file), tilted into the world frame, its
    vertices on the profile and its stated error bounds met."""
    import mitsuba as mi

    from mitsweep.optics import placement_of
    from mitsweep.render.sensor import register

    register()
    monkeypatch.setenv("MITSWEEP_CACHE", "0")
    m = Mirror(kind="conic", radius=20.0, conic=-2.5, rim_radius=30.0, vertex_distance=300.0,
               tilt_deg=tilt)
    shape, info = mirror_shape(m, sag_tol=5e-3, normal_tol=5e-3)
    assert isinstance(shape, mi.Mesh) and info["kind"] == "mesh"
    assert info["sag_error_mm"] <= 5e-3 and info["normal_error_rad"] <= 5e-3
    assert shape.face_count() == info["triangles"]
    pos = np.array(mi.traverse(shape)["vertex_positions"]).reshape(-1, 3)
    local = pos @ placement_of(m).rotation  # world -> local (rotation is orthonormal)
    rho = np.hypot(local[:, 0], local[:, 1])
    # float32 storage: ~1e-6 relative on coordinates of tens of mm.
    np.testing.assert_allclose(local[:, 2], -profile_of(m).sag(rho), atol=5e-5)
    assert isinstance(shape.bsdf(), mi.BSDF)


def test_mirror_shape_of_a_setup_completes_a_hand_written_scene():
    """mirror_shape(setup) + camera_dict + any world: a plain Mitsuba scene. A lamp
    behind the camera is seen only in the mirror's centre, at its radiance (a perfect
    mirror, reflectance 1); the corners see the sky directly."""
    import dataclasses

    import mitsuba as mi

    from mitsweep.config import DEFAULT_SETUP
    from mitsweep.render import camera_dict
    from mitsweep.render.sensor import register

    register()
    s = dataclasses.replace(DEFAULT_SETUP, sensor=dataclasses.replace(
        DEFAULT_SETUP.sensor, resolution=(16, 16), pixel_pitch=0.576))
    shape, info = mirror_shape(s)
    assert info == {"kind": "sphere", "sag_error_mm": 0.0, "normal_error_rad": 0.0}
    scene = mi.load_dict({"type": "scene", "integrator": {"type": "path", "max_depth": 3},
                          "sensor": camera_dict(s, sensor_distance=58.0, spp=4),
                          "mirror": shape,
                          "sky": {"type": "constant", "radiance": 0.3},
                          "lamp": {"type": "disk", "to_world": mi.ScalarTransform4f()
                                   .translate([0.0, 0.0, 1000.0]).rotate([1, 0, 0], 180)
                                   .scale(1500.0),
                                   "emitter": {"type": "area", "radiance": 0.7}}})
    img = np.array(mi.render(scene))[..., :3]
    np.testing.assert_allclose(img[7:9, 7:9], 0.7, rtol=1e-6)
    for corner in (img[0, 0], img[0, -1], img[-1, 0], img[-1, -1]):
        np.testing.assert_allclose(corner, 0.3, rtol=1e-6)


@pytest.mark.parametrize("kind, rim, expected", [
    ("sphere", 25.0, True), ("sphere", 20.0, False), ("paraboloid", 28.25, False)])
def test_analytic_sphere_only_for_a_full_hemisphere(kind, rim, expected):
    if kind == "sphere":
        m = Mirror(kind="sphere", radius=25.0, rim_radius=rim, vertex_distance=327.0)
    else:
        m = Mirror(kind="paraboloid", radius=28.2, conic=-1.0, rim_radius=rim,
                   vertex_distance=352.0)
    assert uses_analytic_sphere(m) is expected
