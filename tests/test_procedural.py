"""The procedural scene family: seeded, regenerable from plain-JSON parameters, objects of
several shapes and materials over the whole depth range, where pixels look, occluding
each other, never in the camera's line of sight; and it renders through the mirror.

The geometric checks use their own ray casts (reflected chief rays of an image grid
against the objects' bounding spheres, segments from the lens to the mirror), not the
placement code's own test.
"""

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from mitsweep.config import DEFAULT_SETUP, Sensor, Sweep
from mitsweep.optics import mirror_point_from_image, placement_of
from mitsweep.render.procedural import (DEFAULT_PARAMS, MATERIALS, SHAPES, procedural_layout,
                                        procedural_scene, resolve_params)

SETUPS = {"sphere": DEFAULT_SETUP}


def _paraboloid():
    from mitsweep.config import load_setup
    from conftest import SCENES

    return load_setup(SCENES / "paraboloid_tilted.toml")


def _reflected_rays(setup, n=240):
    """Mirror points and world-bound directions of an n × n grid of image points
    (tangent coordinates: a sensor 1 mm behind the lens) covering the mirror."""
    t = np.linspace(-0.15, 0.15, n)  # the mirrors subtend tangents < 0.1
    u, v = np.meshgrid(t, t)
    ray = mirror_point_from_image(placement_of(setup.mirror), u.ravel(), v.ravel(), 1.0)
    ok = np.isfinite(ray.surface.rho) & ray.visible
    return ray.surface.position[ok], ray.world_dir[ok]


def _sphere_hits(origins, dirs, centers, radii):
    """(rays, spheres) ray parameters of the first bounding-sphere hit (inf: none)."""
    oc = centers[None, :, :] - origins[:, None, :]
    b = np.einsum("rk,rsk->rs", dirs, oc)
    c = np.einsum("rsk,rsk->rs", oc, oc) - radii[None, :] ** 2
    disc = b * b - c
    t = b - np.sqrt(np.where(disc >= 0, disc, np.nan))
    return np.where((disc >= 0) & (t > 0), t, np.inf)


def test_seed_and_params_regenerate_the_same_scene():
    layout, params = procedural_layout(DEFAULT_SETUP, 7)
    again, params2 = procedural_layout(DEFAULT_SETUP, 7, **params)
    assert json.loads(json.dumps(params)) == params == params2  # plain JSON, resolved
    assert again == layout
    other, _ = procedural_layout(DEFAULT_SETUP, 8)
    assert other != layout


def test_parameters_change_the_scene_as_named():
    layout, params = procedural_layout(DEFAULT_SETUP, 3, objects=5, lights=0, envmap="none",
                                       shapes="sphere")
    assert len(layout["objects"]) == 5 and params["objects"] == 5
    assert layout["lights"] == [] and layout["envmap"] is None
    assert {o["shape"] for o in layout["objects"]} == {"sphere"}


def test_several_shapes_and_diffuse_and_glossy_materials():
    shapes, materials, textured = set(), set(), set()
    for seed in range(4):
        layout, _ = procedural_layout(DEFAULT_SETUP, seed)
        for o in layout["objects"]:
            shapes.add(o["shape"])
            materials.add(o["material"]["kind"])
            textured.add("texture" in o["material"]["colour"])
    assert shapes == set(SHAPES)
    assert materials == set(MATERIALS)
    assert textured == {True, False}


@pytest.mark.parametrize("name", ["sphere", "tilted_paraboloid"])
def test_objects_spread_over_the_setup_depth_range(name):
    setup = DEFAULT_SETUP if name == "sphere" else _paraboloid()
    for seed in range(3):
        layout, _ = procedural_layout(setup, seed)
        depths = np.array([o["depth"] for o in layout["objects"]])
        # 48 log-uniform depths over 0.1-20 m: none below 0.5 m or above 5 m happens with
        # probability (1 - ln 5 / ln 200)^48 < 1e-7 per seed.
        assert depths.min() < 500.0 and depths.max() > 5000.0
        assert depths.min() >= 100.0 and depths.max() <= 20000.0
    # A setup that asks for more depth gets it.
    far = replace(DEFAULT_SETUP, sweep=Sweep(fov_deg=237.0, depth_min=300.0, depth_max=50000.0))
    layout, _ = procedural_layout(far, 0)
    assert layout["depth_range"] == [100.0, 50000.0]


@pytest.mark.parametrize("name", ["sphere", "tilted_paraboloid"])
def test_objects_are_in_view_and_occlude_each_other(name):
    setup = DEFAULT_SETUP if name == "sphere" else _paraboloid()
    layout, _ = procedural_layout(setup, 1)
    things = layout["objects"] + layout["lights"]
    centers = np.array([o["center"] for o in things])
    radii = np.array([o["radius"] for o in things])
    origins, dirs = _reflected_rays(setup)
    t = _sphere_hits(origins, dirs, centers, radii)
    # Every object is where some pixel looks (its bounding sphere meets a reflected ray).
    assert np.all(np.isfinite(t).any(axis=0))
    # Objects occlude each other: many rays meet two or more of them.
    assert np.mean(np.isfinite(t).sum(axis=1) >= 2) > 0.02
    # And they fill a good part of the view.
    assert np.mean(np.isfinite(t).any(axis=1)) > 0.2


@pytest.mark.parametrize("name", ["sphere", "tilted_paraboloid"])
def test_camera_line_of_sight_is_free_and_objects_do_not_overlap(name):
    setup = DEFAULT_SETUP if name == "sphere" else _paraboloid()
    placement = placement_of(setup.mirror)
    rim = setup.mirror.rim_radius
    r, phi = np.meshgrid(np.linspace(0, rim, 12), np.linspace(0, 2 * math.pi, 36))
    mirror = placement.surface(r.ravel() * np.cos(phi.ravel()), r.ravel() * np.sin(phi.ravel()))
    a = setup.lens.aperture_radius
    lens = np.array([0.0, 0.0, setup.mirror.vertex_distance])
    for seed in range(3):
        layout, _ = procedural_layout(setup, seed)
        things = layout["objects"] + layout["lights"]
        centers = np.array([o["center"] for o in things])
        radii = np.array([o["radius"] for o in things])
        for dx, dy in ((0, 0), (a, 0), (-a, 0), (0, a), (0, -a)):
            start = lens + [dx, dy, 0.0]
            seg = mirror.position - start
            length = np.linalg.norm(seg, axis=-1)
            t = _sphere_hits(np.broadcast_to(start, seg.shape), seg / length[:, None],
                             centers, radii)
            assert np.all(t > length[:, None])  # nothing before the mirror
        gap = np.linalg.norm(centers[:, None] - centers[None], axis=-1) - radii[:, None] \
            - radii[None]
        np.fill_diagonal(gap, np.inf)
        assert gap.min() >= 0.0


@pytest.mark.parametrize("params,message", [
    ({"objects": 0}, "objects: must be an integer in [1, 256], got 0"),
    ({"objects": 2.5}, "objects: must be an integer"),
    ({"shapes": "sphere,torus"}, "shapes: unknown 'torus'; allowed: sphere, cube"),
    ({"materials": ""}, "materials: must be a comma-separated list"),
    ({"envmap": "moon"}, "envmap: must be one of random, none"),
    ({"depth_min_mm": 500.0, "depth_max_mm": 100.0}, "depth_max_mm: must be a number in [500"),
    ({"cluster": 1.5}, "cluster: must be a number in [0, 1]"),
    ({"max_depth": 2}, "max_depth: must be an integer in [3, 16]"),
    ({"colour": "red"}, "colour: not a parameter of the procedural family; known: objects"),
])
def test_bad_parameters_name_the_key(params, message):
    with pytest.raises(ValueError) as info:
        resolve_params(**params)
    assert message in str(info.value)


def test_defaults_are_plain_json():
    assert json.loads(json.dumps(DEFAULT_PARAMS)) == DEFAULT_PARAMS == resolve_params()
    assert all(isinstance(v, (int, float, str)) for v in DEFAULT_PARAMS.values())


def test_procedural_scene_loads_in_mitsuba_with_every_object():
    """The objects load beside the mirror and a camera (no render: no kernel to compile),
    each shape as its plugin, the lights and the environment as emitters, in mm."""
    import mitsuba as mi

    from mitsweep.render.api import camera_dict
    from mitsweep.render.scene import build_scene

    objects, params = procedural_scene(DEFAULT_SETUP, 0, lights=3)
    layout, _ = procedural_layout(DEFAULT_SETUP, 0, lights=3)
    cam = camera_dict(DEFAULT_SETUP, sensor_distance=60.0, spp=1)
    scene_dict, info = build_scene(DEFAULT_SETUP, cam, surroundings=False, extra=objects,
                                   max_depth=params["max_depth"])
    assert info["integrator"] == "mirrorpath" and info["max_depth"] == 4
    scene = mi.load_dict(scene_dict, optimize=False)  # cubes sharing a BSDF stay apart
    shapes = {s.id(): s for s in scene.shapes()}
    assert len(shapes) == len(layout["objects"]) + len(layout["lights"]) + 1  # + mirror
    for k, o in enumerate(layout["objects"]):
        shape = shapes[f"object_{k:03d}_{o['shape']}"]
        box = shape.bbox()
        # The shape lies inside its bounding sphere (mm, in the mirror's frame).
        corners = np.array([[box.min[i] if b >> i & 1 else box.max[i] for i in range(3)]
                            for b in range(8)])
        centre = corners.mean(axis=0)
        assert np.linalg.norm(centre - o["center"]) < o["radius"] * 1.01
        assert np.all(np.abs(corners - o["center"]) <= o["radius"] * 1.01 + 1e-3)
    assert len(scene.emitters()) == len(layout["lights"]) + 1  # + the environment map
    assert scene.environment() is not None
    # One BSDF per palette entry, shared by the objects that use it.
    bsdfs = {id(objects[f"object_{k:03d}_{o['shape']}"]["bsdf"]): o["material_index"]
             for k, o in enumerate(layout["objects"])}
    assert len(bsdfs) == len(set(bsdfs.values())) <= params["palette"]


@pytest.mark.slow  # ~30 s loaded, most of it compiling the path integrator's kernel
def test_procedural_scene_renders_through_the_mirror():
    """32 px, 4 spp: every pixel finite, the mirror's image lit, and the depth AOV sees
    objects near and far (and the environment beyond, depth 0 where rays escape)."""
    from mitsweep.render import render_image

    setup = replace(DEFAULT_SETUP, sensor=Sensor(resolution=(32, 32), pixel_pitch=0.27))
    objects, params = procedural_scene(setup, 2)
    assert {k.rsplit("_", 1)[-1] for k in objects if k.startswith("object_")} <= set(SHAPES)
    result = render_image(setup, "pinhole", spp=4, scene={"type": "scene", **objects},
                          max_depth=params["max_depth"], aovs=("depth", "mask"))
    img, mask, depth = result.image, result.aovs["mask"] > 0, result.aovs["depth"]
    assert np.all(np.isfinite(img))
    assert img[mask].mean() > 0.02
    seen = depth[mask & (depth > 0)]
    assert seen.size > 0.2 * mask.sum()
    assert seen.min() < 1000.0 and seen.max() > 3000.0
    assert result.metadata["scene"]["integrator"] == "mirrorpath"
    assert result.metadata["scene"]["max_depth"] == params["max_depth"]
