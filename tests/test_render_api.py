"""Rendering through the mirror: orientation, reference grid, AOVs, EXR and CLI."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import mitsuba  # noqa: E402,F401  (a declared dependency: a missing one must fail)

from mitsweep.config import load_setup  # noqa: E402
from mitsweep.optics import mirror_point_from_image, placement_of  # noqa: E402
from mitsweep.optics.reference import reference_geometry  # noqa: E402
from mitsweep.optics.pixels import image_shape, pixel_to_sensor, sensor_to_pixel  # noqa: E402
from mitsweep.render import (render_image, render_point_source,  # noqa: E402
                             render_to_exr, RenderResult)

SCENES = Path(__file__).resolve().parents[1] / "scenes"


@pytest.fixture(autouse=True)
def _mesh_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("MITSWEEP_CACHE", str(tmp_path_factory.getbasetemp() / "cache"))


def small(name: str, n: int = 64, **scene):
    """A paper setup at n×n pixels covering the same sensor area, coarser meshes."""
    s = load_setup(SCENES / f"{name}.toml")
    W, _ = s.sensor.resolution
    sensor = dataclasses.replace(s.sensor, resolution=(n, n),
                                 pixel_pitch=s.sensor.pixel_pitch * W / n)
    sc = dataclasses.replace(s.scene, mesh_sag_tol=1e-3, mesh_normal_tol=1e-3, **scene)
    return dataclasses.replace(s, sensor=sensor, scene=sc)


def centroid(img):
    rows, cols = np.indices(img.shape)
    s = img.sum()
    return float((cols * img).sum() / s), float((rows * img).sum() / s)


@pytest.mark.parametrize("name", ["sphere", "paraboloid", "paraboloid_tilted"])
@pytest.mark.parametrize("frac_u, frac_v", [(0.3, 0.12), (-0.1, 0.25), (0.2, -0.3)])
def test_marker_lands_where_image_point_predicts(name, frac_u, frac_v):
    """An emitter on the chief ray of (u, v) appears at (u, v): no flip, no swap."""
    s = small(name)
    W, H = s.sensor.resolution
    p = s.sensor.pixel_pitch
    u, v = frac_u * W * p, frac_v * H * p
    i_ref = reference_geometry(s).sensor_distance
    # The tilted mirror's image is off-centre: pull a point that misses it toward the
    # image centre (the camera axis always meets the vertex) until it sees the mirror.
    for _ in range(6):
        if np.isfinite(mirror_point_from_image(placement_of(s.mirror), u, v, i_ref).surface.rho):
            break
        u, v = 0.7 * u, 0.7 * v
    else:
        pytest.fail(f"no point toward the centre from ({frac_u}, {frac_v}) sees the mirror")
    assert max(abs(u), abs(v)) / p >= 6  # still far enough out that a flip would show
    img = render_point_source(s, u, v, 800.0, spp=64, seed=1, mode="pinhole", window_px=16,
                              radius_px=1.5)
    col, row = centroid(img)
    # The marker's image is a ~3 px disk sampled at 64 spp: its centroid scatters by
    # ~0.05 px; a flip of u or v would move it by 2|u|/p >= 12 px.
    want_row, want_col = sensor_to_pixel(u, v, image_shape(s), p)
    assert col == pytest.approx(want_col, abs=0.3)
    assert row == pytest.approx(want_row, abs=0.3)


@pytest.mark.parametrize("mode", ["focused", "stopped", "sweep"])
def test_modes_share_the_pinhole_reference_grid(mode):
    """A point's blurred image is centred where the pinhole puts it (same chief rays)."""
    s = small("sphere", 96)
    u, v = 1.6, -0.9
    ref = render_point_source(s, u, v, 500.0, spp=64, seed=2, mode="pinhole", window_px=24,
                              radius_px=1.5)
    img = render_point_source(s, u, v, 500.0, spp=256, seed=3, mode=mode, window_px=24,
                              radius_px=1.5)
    # Blur is symmetric about the chief ray to first order; 0.35 px allows for the
    # coma-like asymmetry of the off-axis sweep blur and Monte Carlo scatter.
    for a, b in zip(centroid(img), centroid(ref)):
        assert a == pytest.approx(b, abs=0.35)


def test_aovs_give_mirror_mask_and_depth_on_room_walls():
    s = small("paraboloid", 48, objects=0)
    res = render_image(s, "pinhole", spp=4, seed=0, aovs=("depth", "mask"))
    mask, depth = res.aovs["mask"], res.aovs["depth"]
    i_ref = res.metadata["reference_sensor_distance_mm"]
    rows, cols = np.indices(image_shape(s))
    u, v = pixel_to_sensor(rows, cols, image_shape(s), s.sensor.pixel_pitch)
    ray = mirror_point_from_image(placement_of(s.mirror), u, v, i_ref)
    hit = np.isfinite(ray.surface.rho)
    # The 1e-3 mm mesh may disagree with the exact conic only at the rim: < 2 % of pixels.
    assert np.mean(hit != (mask > 0.5)) < 0.02
    both = hit & (mask > 0.5)
    world = ray.surface.position + depth[..., None] * ray.world_dir
    X, Y, Z = s.scene.room_size
    gaps = np.stack([np.abs(np.abs(world[..., 0]) - X / 2), np.abs(np.abs(world[..., 1]) - Y / 2),
                     np.abs(world[..., 2] + 0.4 * Z), np.abs(world[..., 2] - 0.6 * Z)])
    # Every mirror pixel's reflected ray ends on a wall, the floor or the ceiling: within
    # 1 mm over ~2 m (mesh normals good to 1e-3 rad move the end point by up to ~4 mm
    # near the rim, so allow 5 mm at the 99th percentile and check the median at 1 mm).
    closest = gaps.min(axis=0)[both]
    assert np.median(closest) < 1.0
    assert np.percentile(closest, 99) < 5.0
    assert np.all(depth[~(mask > 0.5)] == 0)


def test_exr_carries_image_aovs_and_provenance(tmp_path):
    from mitsweep.io import read_exr

    s = small("sphere", 32)
    res = render_image(s, "sweep", spp=4, seed=9, aovs=("mask",))
    out = render_to_exr(tmp_path / "r.exr", res)
    chans, meta = read_exr(out)
    assert {"R", "G", "B", "mask.Y"} <= set(chans)
    np.testing.assert_allclose(chans["R"], res.image[..., 0])
    for key in ("setup", "mode", "spp", "seed", "sweep", "version", "motion"):
        assert key in meta
    assert meta["mode"] == "sweep" and meta["seed"] == 9 and meta["spp"] == 4
    assert meta["setup"]["mirror"]["radius"] == 25.0


def test_failed_write_leaves_no_partial_exr(tmp_path):
    bad = RenderResult(np.full((8, 8, 3), np.nan, dtype=np.float32), {}, {"mode": "x"})
    target = tmp_path / "r.exr"
    with pytest.raises(ValueError):
        render_to_exr(target, bad)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("kwargs, message", [
    (dict(mode="blurry", spp=4), "mode"),
    (dict(mode="pinhole", spp=0), "spp"),
    (dict(mode="pinhole", spp=4, aovs=("normals",)), "aovs"),
    (dict(mode="stopped", spp=4, f_number=-2.0), "f_number"),
    (dict(mode="pinhole", spp=4, scene_unit="m"), "scene_unit: applies to a user scene"),
])
def test_render_image_rejects_bad_input(kwargs, message):
    with pytest.raises(ValueError, match=message):
        render_image(small("sphere", 16), **kwargs)


def test_cli_render_writes_exr_and_preview(tmp_path, capsys):
    from mitsweep.cli.main import main

    setup = tmp_path / "s.toml"
    setup.write_text((SCENES / "sphere.toml").read_text()
                     .replace("[512, 512]", "[32, 32]").replace("0.018", "0.288"))
    out = tmp_path / "o.exr"
    rc = main(["render", str(setup), "--mode", "focused", "--spp", "4", "--seed", "3",
               "--out", str(out), "--aov", "depth", "--preview", str(tmp_path / "o.png"),
               "--json"])
    assert rc == 0
    assert out.is_file() and (tmp_path / "o.png").is_file()
    assert '"mode": "focused"' in capsys.readouterr().out


@pytest.mark.parametrize("args, message", [
    (["--mode", "sweep", "--out", "/nonexistent-dir/o.exr"], "does not exist"),
    (["--mode", "sweep", "--out", "{tmp}/o.png"], "must end in .exr"),
    (["--mode", "focused", "--f-number", "8", "--out", "{tmp}/o.exr"], "--f-number"),
])
def test_cli_render_bad_input_is_one_line_and_exit_2(tmp_path, capsys, args, message):
    from mitsweep.cli.main import main

    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    rc = main(["render", str(SCENES / "sphere.toml"), *args])
    err = capsys.readouterr().err
    assert rc == 2 and message in err and err.count("\n") == 1
    assert not any(tmp_path.glob("*.exr"))


@pytest.mark.parametrize("key, value, message", [
    ("pixel_pitch", "0.0", "sensor.pixel_pitch"),
    ("resolution", "[0, 16]", "sensor.resolution"),
])
def test_cli_render_bad_setup_values_exit_2(tmp_path, capsys, key, value, message):
    from mitsweep.cli.main import main

    text = (SCENES / "sphere.toml").read_text()
    text = text.replace("pixel_pitch = 0.018", f"pixel_pitch = {value}") if key == "pixel_pitch" \
        else text.replace("resolution = [512, 512]", f"resolution = {value}")
    setup = tmp_path / "bad.toml"
    setup.write_text(text)
    rc = main(["render", str(setup), "--mode", "pinhole", "--out", str(tmp_path / "o.exr")])
    assert rc == 2 and message in capsys.readouterr().err


def test_render_cli_offers_exactly_the_render_modes_and_aovs():
    """The CLI spells the choices out (its parser must not import the renderer); they
    are the render API's."""
    import argparse

    from mitsweep.cli import render as cli_render
    from mitsweep.render import AOV_NAMES, MODES

    p = argparse.ArgumentParser()
    cli_render.add_arguments(p)
    choices = {a.dest: tuple(a.choices) for a in p._actions if a.choices}
    assert choices["mode"] == MODES
    assert choices["aov"] == AOV_NAMES
    from mitsweep.config import SCENE_UNITS
    from mitsweep.render.user_scene import MM_PER_UNIT

    assert choices["scene_unit"] == tuple(MM_PER_UNIT) == SCENE_UNITS


def test_render_cli_runs_a_motion_profile_file_as_the_api_does(tmp_path):
    """``render --motion PROFILE.json``: the sweep of the file's profile, the same image
    as render_image(motion=...) with that profile; a file the setup cannot run is one
    line before any render."""
    from mitsweep.cli.main import main
    from mitsweep.config import setup_to_toml
    from mitsweep.io.exr import read_exr
    from mitsweep.optics.motion import MotionProfile
    from mitsweep.optics.motion_file import save_motion_file
    from mitsweep.optics.sweep import optimal_sweep_range

    setup = small("sphere", 32)
    (tmp_path / "s.toml").write_text(setup_to_toml(setup))
    sr = optimal_sweep_range(setup)
    a, b = sr.sensor_start, sr.sensor_end
    # an uneven profile: most of the exposure near the start of the range
    prof = MotionProfile.tabulated([0.0, 0.7, 1.0], [a, a + 0.2 * (b - a), b])
    save_motion_file(tmp_path / "p.json", prof, exposure_s=None, provenance={"test": 1})
    out = tmp_path / "r.exr"
    assert main(["render", str(tmp_path / "s.toml"), "--mode", "sweep", "--spp", "4",
                 "--motion", str(tmp_path / "p.json"), "--out", str(out)]) == 0
    chans, _ = read_exr(out)
    got = np.stack([chans[c] for c in "RGB"], axis=-1)
    want = render_image(setup, "sweep", spp=4, motion=prof).image
    np.testing.assert_array_equal(got, want)
    linear = render_image(setup, "sweep", spp=4).image
    assert np.abs(linear - want).max() > 0      # the profile changed the image

    bad = MotionProfile.tabulated([0.0, 1.0], [setup.lens.focal_length * 0.9, b])
    save_motion_file(tmp_path / "bad.json", bad, exposure_s=None, provenance={})
    assert main(["render", str(tmp_path / "s.toml"), "--mode", "sweep", "--spp", "4",
                 "--motion", str(tmp_path / "bad.json"), "--out",
                 str(tmp_path / "bad.exr")]) == 2
    assert not (tmp_path / "bad.exr").exists()
