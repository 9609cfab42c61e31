"""Small frictions of issue 25: ``render --resolution``, unknown setup names, an FOV beyond
the mirror's reach refused when a setup is read, ``stack_channels`` in ``mitsweep.io``."""

from __future__ import annotations

import math

import numpy as np
import pytest
from cli_contract import refused

from mitsweep.cli.common import load_setup_arg
from mitsweep.cli.main import main
from mitsweep.config import MAX_RESOLUTION, SetupError, setup_from_dict
from mitsweep.optics import max_fov_deg
from mitsweep.optics.outline import predicted_outline
from mitsweep.optics.pixels import optical_center_px
from mitsweep.resources import bundled_setup, bundled_setup_names

SPHERE = bundled_setup("sphere")


def _outline_px(setup) -> np.ndarray:
    """The mirror's predicted outline as (row, col) pixels of the setup's frame, (N, 2)."""
    s = setup.sensor
    pts, _ = predicted_outline(setup).offsets_px(s.pixel_pitch)
    return pts + np.array(optical_center_px((s.height, s.width), s.center_offset_px))


def _inside(points: np.ndarray, width: int, height: int) -> np.ndarray:
    """Which points lie within the frame's pixel area ([-0.5, side - 0.5] in centres)."""
    rows, cols = points[:, 0], points[:, 1]
    return (rows >= -0.5) & (rows <= height - 0.5) & (cols >= -0.5) & (cols <= width - 0.5)


@pytest.mark.parametrize("name", bundled_setup_names())
@pytest.mark.parametrize("resolution", [(128, 128), (128, 64), (50, 300), (1024, 768)])
def test_a_new_resolution_keeps_what_the_setups_frame_shows(name, resolution):
    """At any resolution the scaled pitch keeps in frame every point of the mirror's
    outline that the setup's own frame shows: all of it for the untilted setups (the
    tilted paraboloid's 512 px frame cuts its far side, as the setup chose)."""
    from dataclasses import replace

    setup = load_setup_arg(name)
    shown = _inside(_outline_px(setup), *setup.sensor.resolution)
    if not setup.mirror.tilt_deg:
        assert shown.all()
    W, H = resolution
    scaled = replace(setup, sensor=setup.sensor.at_resolution(W, H))
    assert scaled.sensor.resolution == (W, H)
    scale = max(setup.sensor.width / W, setup.sensor.height / H)
    assert scaled.sensor.pixel_pitch == pytest.approx(setup.sensor.pixel_pitch * scale,
                                                      rel=1e-15)
    # the same outline points in mm (index for index), now on the scaled pixel grid
    assert _inside(_outline_px(scaled), W, H)[shown].all()


def test_a_new_resolution_keeps_the_centre_offset_in_mm():
    """A calibrated axis offset stays at the same sensor point: its pixels scale with
    1/s (s the pitch's scale)."""
    from mitsweep.config import Sensor

    s = Sensor(resolution=(400, 300), pixel_pitch=0.01, center_offset_px=(12.0, -8.0))
    t = s.at_resolution(100, 100)   # s = max(4, 3) = 4
    assert t.pixel_pitch == pytest.approx(0.04, rel=1e-15)
    mm = lambda x: np.array(x.center_offset_px) * x.pixel_pitch
    np.testing.assert_allclose(mm(t), mm(s), rtol=1e-15)


def test_render_at_a_smaller_resolution_shows_the_whole_mirror(tmp_path, capsys):
    """A real pinhole render at 128 x 128 of the 512 x 512 sphere: the pitch is 4 x the
    setup's (said in the EXR's provenance and the JSON), and the rendered mask (pixels
    whose chief ray hits the mirror) is the predicted disc, clear of the frame's edges.

    Tolerance: the mask samples the pixel centres, so its area differs from the
    outline's by at most the pixels the outline crosses (~ its perimeter, 2 pi r);
    measured 8 px of 10 444."""
    import json

    from mitsweep.io import read_exr

    out = tmp_path / "small.exr"
    rc = main(["render", str(SPHERE), "--mode", "pinhole", "--spp", "1", "--resolution",
               "128", "128", "--aov", "mask", "--out", str(out), "--json"])
    assert rc == 0
    summary = json.loads(capsys.readouterr().out)
    chans, meta = read_exr(out)
    assert chans["R"].shape == (128, 128)
    r = meta["resolution"]
    assert summary["resolution"] == r
    assert (r["setup_resolution_px"], r["resolution_px"]) == ([512, 512], [128, 128])
    assert r["pitch_scale"] == pytest.approx(4.0, rel=1e-15)
    assert r["pixel_pitch_mm"] == meta["setup"]["sensor"]["pixel_pitch"] == \
        pytest.approx(4 * 0.018, rel=1e-15)
    scaled = setup_from_dict(meta["setup"])
    outline = _outline_px(scaled)
    assert _inside(outline, 128, 128).all()
    mask = chans["mask.Y"] > 0.5
    assert not (mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any())
    radius = predicted_outline(scaled).equivalent_radius_px(scaled.sensor.pixel_pitch)
    assert 50.0 < radius < 60.0   # 230.6 px at the setup's pitch, / 4
    assert abs(mask.sum() - math.pi * radius ** 2) < 2 * math.pi * radius
    assert np.all(np.isfinite(chans["R"])) and chans["R"][mask].mean() > 0


@pytest.mark.parametrize("argv, says", [
    (["--resolution", str(MAX_RESOLUTION + 1), "128"], f"at most {MAX_RESOLUTION} px"),
    (["--resolution", "0", "128"], "must be > 0"),
    (["--resolution", "128"], "expected 2 arguments"),
])
def test_render_refuses_a_bad_resolution_in_one_line(tmp_path, capsys, argv, says):
    line = refused(capsys, ["render", SPHERE, "--mode", "pinhole", "--out",
                            tmp_path / "x.exr", *argv])
    assert "--resolution" in line and says in line
    assert not (tmp_path / "x.exr").exists()


def test_an_unknown_setup_name_lists_the_bundled_ones(capsys):
    line = refused(capsys, ["sweep-range", "spherre"])
    assert "spherre: no such setup file, nor a bundled setup name" in line
    assert f"(bundled: {', '.join(bundled_setup_names())})" in line
    assert {"sphere", "paraboloid"} <= set(bundled_setup_names())


def _sphere_with_fov(fov: float) -> dict:
    return {"name": "wide", "mirror": {"kind": "sphere", "radius": 25.0,
                                       "center_distance": 352.0},
            "sweep": {"fov_deg": fov}}


def _toml(tmp_path, table: dict) -> str:
    """The table as a setup file, written as a user would (not through setup_from_dict,
    which refuses an unreachable FOV itself)."""
    import tomli_w

    path = tmp_path / "wide.toml"
    path.write_text(tomli_w.dumps(table))
    return str(path)


def test_setup_from_dict_refuses_an_unreachable_fov_at_construction():
    with pytest.raises(SetupError, match=r"^sweep\.fov_deg: 355° is beyond .* the largest "
                                         r"FOV it gives is 351\.85°$"):
        setup_from_dict(_sphere_with_fov(355.0))


def test_an_unreachable_fov_is_refused_when_the_setup_is_read(tmp_path, capsys):
    """The paper's sphere seen from 352 mm reaches 351.85 deg: 355 deg is refused at
    load, naming the key and the largest FOV (the optics' own number, to the two
    decimals printed); every command reads its setup this way."""
    reach = max_fov_deg(setup_from_dict(_sphere_with_fov(237.0)))
    assert reach == pytest.approx(351.85, abs=0.01)
    path = _toml(tmp_path, _sphere_with_fov(355.0))
    with pytest.raises(SetupError, match=rf"^sweep\.fov_deg: 355° is beyond .* "
                                         rf"the largest FOV it gives is {reach:.2f}°$"):
        load_setup_arg(path)
    for command in (["sweep-range", path], ["render", path, "--mode", "pinhole",
                                            "--out", tmp_path / "x.exr"]):
        line = refused(capsys, command)
        assert "sweep.fov_deg" in line and f"{reach:.2f}°" in line
    assert load_setup_arg(_toml(tmp_path, _sphere_with_fov(351.0))).sweep.fov_deg == 351.0


def test_a_tilted_mirrors_fov_is_checked_in_its_tilt_plane(tmp_path):
    """The tilted paraboloid's in-plane reach (~188 deg): 200 deg is refused at load."""
    from mitsweep.config import setup_to_dict

    table = setup_to_dict(load_setup_arg("paraboloid_tilted"))
    reach = max_fov_deg(setup_from_dict(table))
    table["sweep"]["fov_deg"] = 200.0
    with pytest.raises(SetupError, match=rf"^sweep\.fov_deg: .* in its tilt plane; the "
                                         rf"largest FOV it gives is {reach:.2f}°$"):
        load_setup_arg(_toml(tmp_path, table))


def test_stack_channels_is_exported_from_io():
    from mitsweep.io import stack_channels

    chans = {c: np.full((2, 3), k, np.float32) for k, c in enumerate("RGB")}
    assert stack_channels(chans).shape == (2, 3, 3)
    assert stack_channels(chans)[0, 0].tolist() == [0.0, 1.0, 2.0]
