"""A user's Mitsuba scene through the mirror: units, placement, every mode with AOVs,
closed-form radiance and depth, provenance, and the user errors."""

from __future__ import annotations

import dataclasses
import hashlib
import logging
from pathlib import Path

import numpy as np
import pytest

import mitsuba as mi  # noqa: F401  (a declared dependency: a missing one must fail)

from mitsweep.config import DEFAULT_SETUP, Placement, load_setup
from mitsweep.optics import mirror_point_from_image, placement_of
from mitsweep.optics.pixels import image_shape, pixel_to_sensor
from mitsweep.render import (MODES, UserSceneError, load_user_scene, render_image,
                             render_to_exr, user_scene)
from mitsweep.render.sensor import register

SCENES = Path(__file__).resolve().parents[1] / "scenes"


@pytest.fixture(autouse=True)
def _mesh_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("MITSWEEP_CACHE", str(tmp_path_factory.getbasetemp() / "cache"))


def small(n: int = 24, setup=DEFAULT_SETUP, **scene):
    """The paper's sphere setup at n×n pixels over the same sensor area."""
    W, _ = setup.sensor.resolution
    sensor = dataclasses.replace(setup.sensor, resolution=(n, n),
                                 pixel_pitch=setup.sensor.pixel_pitch * W / n)
    sc = dataclasses.replace(setup.scene, mesh_sag_tol=1e-3, mesh_normal_tol=1e-3, **scene)
    return dataclasses.replace(setup, sensor=sensor, scene=sc)


def T():
    register()
    return mi.ScalarTransform4d()


def world(mm_per_unit: float) -> dict:
    """One scene, written in a unit of ``mm_per_unit`` mm: an emissive checkered sphere
    around everything, a board, a diffuse ball under a point light, a user sensor and
    integrator (to be replaced)."""
    k = 1.0 / mm_per_unit
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "camera": {"type": "perspective", "fov": 30,
                   "film": {"type": "hdrfilm", "width": 8, "height": 8}},
        "enclosure": {"type": "sphere", "radius": 3000.0 * k, "flip_normals": True,
                      "bsdf": {"type": "diffuse", "reflectance": 0.0},
                      "emitter": {"type": "area", "radiance": {
                          "type": "checkerboard", "color0": 0.2, "color1": 0.9,
                          "to_uv": T().scale([12.0, 12.0, 1.0])}}},
        "board": {"type": "rectangle",
                  "to_world": T().translate([-500.0 * k, -200.0 * k, -300.0 * k])
                  .rotate([0.0, 1.0, 0.0], 30.0).scale([200.0 * k, 200.0 * k, 1.0]),
                  "emitter": {"type": "area", "radiance": 1.5}},
        "ball": {"type": "sphere", "center": [600.0 * k, 300.0 * k, 100.0 * k],
                 "radius": 150.0 * k, "bsdf": {"type": "diffuse", "reflectance": 0.6}},
        "light": {"type": "point", "position": [0.0, 1500.0 * k, 800.0 * k],
                  "intensity": {"type": "rgb", "value": [5e5 * k * k] * 3}},
    }


def as_xml(scene: dict, path: Path) -> Path:
    """``scene`` written as XML by Mitsuba's own writer."""
    register()
    cfg = mi.parser.ParserConfig(mi.variant())
    path.write_text(mi.parser.write_string(mi.parser.parse_dict(cfg, scene)))
    return path


@pytest.mark.parametrize("mode", MODES)
def test_metre_scene_renders_the_mm_scene_in_every_mode_with_aovs(tmp_path, mode):
    """The same world in mm (a dict) and in metres (an XML file) renders the same image
    and AOVs with the same seed, up to float32 rounding of the converted geometry."""
    s = small()
    kw = dict(spp=8, seed=5, aovs=("depth", "mask"))
    mm = render_image(s, mode, scene=world(1.0), scene_unit="mm", **kw)
    m = render_image(s, mode, scene=as_xml(world(1000.0), tmp_path / "w.xml"),
                     scene_unit="m", **kw)
    assert mm.image.max() > 0.1  # the world is in view and lit
    # Each converted value (0.4 m x 1000 in float64, then float32) equals the mm scene's
    # to float32 rounding, so samples take the same paths: the images agree to float32
    # rounding (measured: one ulp in 0.2 % of the values, depth identical).
    np.testing.assert_allclose(m.image, mm.image, rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(m.aovs["mask"], mm.aovs["mask"])
    np.testing.assert_allclose(m.aovs["depth"], mm.aovs["depth"], rtol=1e-6)
    meta = m.metadata["user_scene"]
    assert meta["unit"] == "m" and meta["mm_per_unit"] == 1000.0
    assert sorted(meta["replaced"]) == ["integrator 'path'", "sensor 'perspective'"]
    assert m.metadata["scene"]["max_depth"] == 4  # the user's 3 plus the mirror's bounce


def test_participating_media_convert_their_density_and_use_volpath(tmp_path):
    """A fog ball (sigma_t per scene unit) in metres renders as its mm copy: the density
    is divided by 1000 with the lengths multiplied by 1000 (else the fog would be 10^6
    times denser: opaque)."""
    def foggy(mm_per_unit):
        d = world(mm_per_unit)
        d["fog"] = {"type": "sphere", "center": [0.0, -400.0 / mm_per_unit, 0.0],
                    "radius": 350.0 / mm_per_unit, "bsdf": {"type": "null"},
                    "interior": {"type": "homogeneous", "sigma_t": 0.004 * mm_per_unit,
                                 "albedo": 0.5}}
        return d

    s = small(32)
    mm = render_image(s, "pinhole", spp=8, seed=3, scene=foggy(1.0))
    m = render_image(s, "pinhole", spp=8, seed=3, scene=as_xml(foggy(1000.0), tmp_path / "f.xml"),
                     scene_unit="m")
    clear = render_image(s, "pinhole", spp=8, seed=3, scene=world(1.0))
    assert mm.metadata["scene"]["integrator"] == "volpath"
    assert np.abs(mm.image - clear.image).max() > 0.1  # the fog is seen
    # Measured: 6e-8 at most (float32 rounding of the converted distances).
    np.testing.assert_allclose(m.image, mm.image, rtol=1e-5, atol=1e-6)


def test_centimetre_placed_scene_matches_the_mm_scene_moved_by_hand():
    """unit cm and a placement (rotation, then translation in mm) equal the mm scene with
    the same transform written into it."""
    s = small(16)
    place = Placement(translate=(40.0, -30.0, 20.0), rotate_deg=(0.0, 0.0, 25.0))
    moved = world(1.0)
    for name in ("enclosure", "board"):
        base = moved[name].get("to_world", T())
        moved[name]["to_world"] = T().translate([40.0, -30.0, 20.0]).rotate(
            [0.0, 0.0, 1.0], 25.0) @ base
    c, r = np.cos(np.radians(25.0)), np.sin(np.radians(25.0))
    x, y, z = moved["ball"]["center"]
    moved["ball"]["center"] = [c * x - r * y + 40.0, r * x + c * y - 30.0, z + 20.0]
    x, y, z = moved["light"]["position"]
    moved["light"]["position"] = [c * x - r * y + 40.0, r * x + c * y - 30.0, z + 20.0]
    ref = render_image(s, "pinhole", spp=4, seed=1, scene=moved)
    s_cm = dataclasses.replace(s, scene=dataclasses.replace(s.scene, unit="cm", placement=place))
    got = render_image(s_cm, "pinhole", spp=4, seed=1, scene=world(10.0))
    # Measured: 3.0e-8 at most (8e-8 relative; float32 rounding of the converted and
    # composed transforms), as for the fog test above.
    np.testing.assert_allclose(got.image, ref.image, rtol=1e-5, atol=1e-6)


def test_uniform_emissive_world_gives_its_radiance_through_the_mirror(monkeypatch):
    """Inside a uniformly emissive sphere every camera ray, through the perfect mirror
    (reflectance 1) or past it, returns the emitted radiance: exactly, in every mode and
    over several passes."""
    import mitsweep.render.api as api

    monkeypatch.setattr(api, "MAX_LANES", 24 * 24 * 4)  # 4 spp per pass: 3 passes
    radiance = [0.25, 0.5, 0.75]
    scene = {"type": "scene",
             "world": {"type": "sphere", "radius": 5.0, "flip_normals": True,
                       "emitter": {"type": "area", "radiance": {"type": "rgb",
                                                                "value": radiance}}}}
    s = small()
    for mode in MODES:
        res = render_image(s, mode, spp=12, seed=2, scene=scene, scene_unit="m",
                           aovs=("mask",), sampler="independent")
        x, y, w, h = res.metadata["crop"]
        window = res.image[y:y + h, x:x + w]
        mirror = window[res.aovs["mask"][y:y + h, x:x + w] > 0.5]
        assert mirror.size > 0
        # float32 sums of equal values over passes: exact to rounding.
        np.testing.assert_allclose(mirror, np.broadcast_to(radiance, mirror.shape), rtol=1e-6)
        np.testing.assert_allclose(window.reshape(-1, 3), np.broadcast_to(radiance, (w * h, 3)),
                                   rtol=1e-6)


def _ray_sphere(p, w, centre, radius):
    """Distance along unit w from p (inside the sphere) to the sphere."""
    q = p - centre
    b = np.sum(q * w, axis=-1)
    c = np.sum(q * q, axis=-1) - radius ** 2
    return -b + np.sqrt(b * b - c)


def test_depth_aov_is_the_analytic_distance_to_a_sphere_and_a_plane():
    """Depth along each pixel's reflected chief ray (optics' chief rays, float64)
    equals the distance to a placed enclosing sphere or, where nearer, a wall plane."""
    s = small(32)
    centre_mm = np.array([100.0, -50.0, 0.0])
    scene = {"type": "scene",
             "world": {"type": "sphere", "radius": 2.0, "flip_normals": True,
                       "emitter": {"type": "area", "radiance": 1.0}},
             # A wall at x = 0.8 m (before the placement), facing -x.
             "wall": {"type": "rectangle", "to_world": T().translate([0.8, 0.0, 0.0])
                      .rotate([0.0, 1.0, 0.0], -90.0).scale(3.0)}}
    s = dataclasses.replace(s, scene=dataclasses.replace(
        s.scene, unit="m", placement=Placement(translate=tuple(centre_mm))))
    res = render_image(s, "pinhole", spp=1, scene=scene, aovs=("depth", "mask"))
    i_ref = res.metadata["reference_sensor_distance_mm"]
    rows, cols = np.indices(image_shape(s))
    u, v = pixel_to_sensor(rows, cols, image_shape(s), s.sensor.pixel_pitch)
    ray = mirror_point_from_image(placement_of(s.mirror), u, v, i_ref)
    hit = np.isfinite(ray.surface.rho)
    mask = res.aovs["mask"] > 0.5
    # The analytic sphere's rim: pixels whose centre grazes it may differ.
    assert np.mean(hit != mask) < 0.01
    both = hit & mask
    p, w = ray.surface.position[both], ray.world_dir[both]
    t = _ray_sphere(p, w, centre_mm, 2000.0)
    x_wall = 800.0 + centre_mm[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t_wall = (x_wall - p[:, 0]) / w[:, 0]
    end = p + t_wall[:, None] * w
    on_wall = (t_wall > 0) & (np.abs(end[:, 1] - centre_mm[1]) < 3000) & \
        (np.abs(end[:, 2] - centre_mm[2]) < 3000)
    want = np.where(on_wall, np.minimum(t, t_wall), t)
    assert on_wall.any() and (~on_wall).any()
    # Mitsuba's float32 mirror points and normals (~2e-6 rad) over ~2 m: measured
    # 0.007 mm at most; a 1 mm error in the unit or the placement would show 100 times.
    np.testing.assert_allclose(res.aovs["depth"][both], want, atol=0.02)


def test_xml_defaults_relative_files_and_replacements_are_resolved(tmp_path, caplog):
    """<default>s resolve as in Mitsuba, a PLY beside the file is found from any
    directory, and each replaced sensor and integrator is logged."""
    register()
    (tmp_path / "meshes").mkdir()
    mi.load_dict({"type": "cube"}).write_ply(str(tmp_path / "meshes" / "cube.ply"))
    xml = tmp_path / "scene.xml"
    xml.write_text("""<scene version="3.0.0">
  <default name="r" value="0.25"/>
  <integrator type="volpath"/>
  <sensor type="thinlens"><film type="hdrfilm"/></sensor>
  <shape type="ply" id="box"><string name="filename" value="meshes/cube.ply"/>
    <transform name="to_world"><translate x="1"/></transform></shape>
  <shape type="sphere" id="mirror"><float name="radius" value="$r"/>
    <point name="center" x="0" y="1" z="0"/>
    <emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
  <emitter type="envmap" id="sky"><string name="filename" value="meshes/../sky.exr"/></emitter>
</scene>""")
    mi.Bitmap(np.full((4, 8, 3), 0.5, dtype=np.float32)).write(str(tmp_path / "sky.exr"))
    with caplog.at_level(logging.INFO, logger="mitsweep.render.user_scene"):
        u = load_user_scene(small(), str(xml), unit="m")
    assert any("volpath" in r.message and "replaced" in r.message for r in caplog.records)
    assert any("thinlens" in r.message and "replaced" in r.message for r in caplog.records)
    # A user shape named 'mirror' is renamed: the name is the setup's mirror's.
    assert set(u.objects) == {"box", "user_mirror", "sky"}
    box = u.objects["box"].bbox()
    np.testing.assert_allclose([box.min, box.max], [[0, -1000, -1000], [2000, 1000, 1000]])
    ball = u.objects["user_mirror"].bbox()
    np.testing.assert_allclose([ball.min, ball.max], [[-250, 750, -250], [250, 1250, 250]],
                               rtol=1e-6)
    assert u.provenance["sha256"] == hashlib.sha256(xml.read_bytes()).hexdigest()
    assert u.provenance["source"] == str(xml.resolve())
    assert user_scene(small(), str(xml), unit="m").keys() == u.objects.keys()


def test_shipped_example_scene_spans_the_depth_range_in_metres():
    """scenes/garden_m.xml (metres): everything the mirror sees is a shape, from the near
    ball (0.25 m) to the sky dome (8 m)."""
    res = render_image(small(32), "pinhole", spp=4, scene=SCENES / "garden_m.xml",
                       scene_unit="m", aovs=("depth",))
    assert res.metadata["user_scene"]["view"]["in_view_fraction"] == 1.0
    depth = res.aovs["depth"][res.aovs["depth"] > 0]
    # Mirror points lie within 36 mm of the origin, the dome's centre.
    assert 150.0 < depth.min() < 400.0 and 7000.0 < depth.max() < 8036.0
    assert np.isfinite(res.image).all() and res.image.max() > 0.3


def test_exr_records_the_scene_file_and_its_hash(tmp_path):
    from mitsweep.io import read_exr

    xml = as_xml(world(1000.0), tmp_path / "w.xml")
    res = render_image(small(16), "sweep", spp=2, scene=xml, scene_unit="m", aovs=("depth",))
    _, meta = read_exr(render_to_exr(tmp_path / "r.exr", res))
    us = meta["user_scene"]
    assert us["source"] == str(xml.resolve())
    assert us["sha256"] == hashlib.sha256(xml.read_bytes()).hexdigest()
    assert us["unit"] == "m" and "sensor 'perspective'" in us["replaced"]
    dict_res = render_image(small(16), "pinhole", spp=1, scene=world(1.0))
    assert dict_res.metadata["user_scene"]["source"] == "dict"
    assert len(dict_res.metadata["user_scene"]["sha256"]) == 64


def test_dict_hash_is_stable_and_follows_the_content():
    """The SHA-256 of a dict scene depends on its values (transforms, bitmaps), not on
    object identities: equal dicts hash equal, a changed value changes it."""
    register()

    def with_sky(value):
        d = world(1.0)
        d["sky"] = {"type": "envmap", "bitmap": mi.Bitmap(np.full((2, 4, 3), value,
                                                                  dtype=np.float32))}
        return d

    def sha(d):
        return load_user_scene(small(8), d).provenance["sha256"]

    assert sha(with_sky(0.5)) == sha(with_sky(0.5))
    assert sha(with_sky(0.5)) != sha(with_sky(0.6))
    moved = with_sky(0.5)
    moved["board"]["to_world"] = T().translate([0.0, 0.0, 1.0]) @ moved["board"]["to_world"]
    assert sha(moved) != sha(with_sky(0.5))


def test_setup_scene_file_is_found_beside_the_setup(tmp_path, monkeypatch):
    """[scene] file (relative to the setup file) and unit drive render_image alone."""
    as_xml(world(1000.0), tmp_path / "w.xml")
    text = (SCENES / "sphere.toml").read_text().replace("[512, 512]", "[16, 16]") \
        .replace("0.018", "0.576")
    if "[scene]" in text:
        text = text.replace("[scene]", '[scene]\nfile = "w.xml"\nunit = "m"', 1)
    else:
        text += '\n[scene]\nfile = "w.xml"\nunit = "m"\n'
    (tmp_path / "s.toml").write_text(text)
    monkeypatch.chdir(SCENES)
    s = load_setup(tmp_path / "s.toml")
    assert s.scene.file == str(tmp_path / "w.xml")
    res = render_image(s, "pinhole", spp=2)
    assert res.metadata["user_scene"]["unit"] == "m" and res.image.max() > 0.1


def test_mirror_mesh_renders_a_user_scene_with_the_disk_cache_off(tmp_path, monkeypatch):
    """A meshed mirror (paraboloid) is built in memory, nothing written, when the cache
    is off; its error bound is reported."""
    monkeypatch.setenv("MITSWEEP_CACHE", "0")
    monkeypatch.chdir(tmp_path)
    s = small(16, setup=load_setup(SCENES / "paraboloid.toml"))
    scene = {"type": "scene", "world": {"type": "constant", "radiance": 0.5}}
    res = render_image(s, "pinhole", spp=2, scene=scene, aovs=("mask",))
    info = res.metadata["scene"]["mirror"]
    assert info["kind"] == "mesh" and 0 < info["sag_error_mm"] <= 1e-3
    assert 0 < info["normal_error_rad"] <= 1e-3
    assert list(tmp_path.iterdir()) == []
    assert res.aovs["mask"].sum() > 0
    np.testing.assert_allclose(res.image[res.aovs["mask"] > 0.5], 0.5, rtol=1e-6)


# --- bad input: one line, exit 2 --------------------------------------------------------

def _blocked():
    """A card 100 mm in front of the mirror vertex, on the camera axis."""
    return {"type": "scene", "light": {"type": "constant"},
            "card": {"type": "rectangle", "to_world": T().translate([0.0, 0.0, 100.0]).scale(20.0)}}


@pytest.mark.parametrize("scene, unit, message", [
    (_blocked, "mm", "'card' lies between the lens and the mirror"),
    # The metre world read as mm: the board and the ball shrink inside the mirror.
    (lambda: {k: v for k, v in world(1000.0).items() if k not in ("light", "enclosure")}, "mm",
     "nothing in the mirror's view"),
    (lambda: {"type": "scene", "ball": {"type": "sphere"}}, "mm", "no emitter"),
    (lambda: {"type": "scene", "b": {"type": "blobby"}}, "mm", 'Plugin "blobby" not found'),
    (lambda: {"type": "shape"}, "mm", "needs \"type\": \"scene\""),
    (lambda: {"type": "scene", "g": {"type": "shapegroup", "s": {"type": "sphere"}},
              "i": {"type": "instance", "shapegroup": {"type": "ref", "id": "g"}}}, "m",
     "instancing"),
])
def test_unusable_dict_scenes_raise_one_line_user_errors(scene, unit, message):
    with pytest.raises(UserSceneError, match=message.replace("(", r"\(")) as err:
        render_image(small(16), "pinhole", spp=1, scene=scene(), scene_unit=unit)
    assert "\n" not in str(err.value)


def _cli(args, capsys):
    from mitsweep.cli.main import main

    rc = main(["render", str(SCENES / "sphere.toml"), "--mode", "pinhole", "--spp", "1", *args])
    return rc, capsys.readouterr().err


@pytest.mark.parametrize("content, message", [
    ("this is no scene\n", "not a Mitsuba XML scene"),
    ("<scene version='3.0.0'><shape type='ply'><string name='filename' value='gone.ply'/>"
     "</shape></scene>", "gone.ply"),
    ("<scene version='3.0.0'><shape type='sphere'><bsdf type='diffuse'><texture "
     "type='bitmap' name='reflectance'><string name='filename' value='gone.png'/></texture>"
     "</bsdf></shape></scene>", "gone.png"),
    ("<scene version='3.0.0'><shape type='blobby'/></scene>", 'Plugin "blobby" not found'),
    ("<scene version='3.0.0'><emitter type='constant'/><shape type='rectangle'><transform "
     "name='to_world'><scale value='20'/><translate z='100'/></transform></shape></scene>",
     "between the lens and the mirror"),
    ("<scene version='3.0.0'><emitter type='point'/><shape type='sphere'><point "
     "name='center' x='0' y='0' z='-5000'/></shape></scene>", "nothing in the mirror's view"),
    ("<scene version='3.0.0'><shape type='sphere'/", "line"),
])
def test_cli_bad_scene_file_is_one_line_and_exit_2(tmp_path, capsys, content, message):
    xml = tmp_path / "bad.xml"
    xml.write_text(content)
    rc, err = _cli(["--scene", str(xml), "--out", str(tmp_path / "o.exr")], capsys)
    assert rc == 2 and err.count("\n") == 1 and err.startswith("mitsweep: error: ")
    assert message in err and str(xml) in err
    assert not (tmp_path / "o.exr").exists()


def test_cli_missing_scene_file_and_stray_unit_exit_2(tmp_path, capsys):
    rc, err = _cli(["--scene", str(tmp_path / "none.xml"), "--out", str(tmp_path / "o.exr")],
                   capsys)
    assert rc == 2 and "no such scene file" in err and err.count("\n") == 1
    rc, err = _cli(["--scene-unit", "m", "--out", str(tmp_path / "o.exr")], capsys)
    assert rc == 2 and "--scene-unit" in err


def test_cli_renders_a_scene_file_quietly(tmp_path):
    """Through a real process: exit 0, the EXR written, nothing on stderr."""
    from conftest import run_cli

    xml = as_xml(world(1000.0), tmp_path / "w.xml")
    setup = tmp_path / "s.toml"
    setup.write_text((SCENES / "sphere.toml").read_text().replace("[512, 512]", "[16, 16]")
                     .replace("0.018", "0.576"))
    rc, out, err = run_cli("render", setup, "--mode", "focused", "--spp", "2", "--scene", xml,
                           "--scene-unit", "m", "--aov", "depth", "--out", tmp_path / "o.exr",
                           "--json")
    assert rc == 0, err
    assert err == "" and (tmp_path / "o.exr").is_file()
    assert '"unit": "m"' in out


def test_user_scenes_get_the_integrator_differentiable_through_the_mirror():
    """With a finite depth (the user's integrator's, plus the mirror's bounce) a user
    scene is rendered by ``mirrorpath`` (``path``'s image; the *_ad_* variant of the
    tests), and a sweep gradient of the scene mitsweep builds from it passes through the
    mirror; an unlimited depth keeps ``path`` (whose sweep gradient through the mirror
    is refused: tests/test_render_lit_grad.py)."""
    import drjit as dr

    from mitsweep.render import camera_dict, mode_camera
    from mitsweep.render.scene import build_scene

    s = small(8)
    assert render_image(s, "pinhole", spp=1, scene=world(1.0)).metadata["scene"][
        "integrator"] == "mirrorpath"
    kw, _ = mode_camera(s, "sweep", None, None)
    cam = camera_dict(s, spp=4, sampler="independent", **kw)
    objects = load_user_scene(s, world(1.0)).objects
    assert build_scene(s, cam, surroundings=False, extra=objects,
                       max_depth=-1)[1]["integrator"] == "path"
    d, info = build_scene(s, cam, surroundings=False, extra=objects, max_depth=4)
    assert info["integrator"] == "mirrorpath"
    scene = mi.load_dict(d)
    params = mi.traverse(scene)
    dr.enable_grad(params["sensor.sensor_end"])
    params.update()
    try:
        img = mi.render(scene, params, seed=1, seed_grad=2)
        dr.backward(dr.sum(img, axis=None))
        g = float(dr.grad(params["sensor.sensor_end"])[0])
    finally:
        dr.disable_grad(params["sensor.sensor_end"])
    assert np.isfinite(g) and g != 0.0
