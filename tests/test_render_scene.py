"""The room around the mirror: board placement, lighting and integrator depth."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from mitsweep.config import SetupError, load_setup
from mitsweep.render.scene import board_layout, integrator_depth

SCENES = Path(__file__).resolve().parents[1] / "scenes"


def _with_scene(name, **kw):
    s = load_setup(SCENES / f"{name}.toml")
    return dataclasses.replace(s, scene=dataclasses.replace(s.scene, **kw))


@pytest.mark.parametrize("name", ["sphere", "paraboloid", "paraboloid_tilted"])
@pytest.mark.parametrize("seed", [0, 3])
def test_boards_span_10cm_to_1500mm_and_stay_out_of_the_camera_view(name, seed):
    s = _with_scene(name, objects=8, texture_seed=seed)
    boards = board_layout(s)
    assert len(boards) == 8
    depths = [np.linalg.norm(b["center"]) for b in boards]
    assert min(depths) == pytest.approx(100.0) and max(depths) <= 1500.0 + 1e-9
    keep_out = s.mirror.rim_radius + 15.0
    for b in boards:
        # The board faces the mirror and none of its corners enters the cylinder the
        # camera looks through.
        assert np.dot(b["normal"], -b["center"]) > 0
        n = b["normal"]
        t1 = np.cross(n, [0.0, 0.0, 1.0])
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(n, t1)
        for a in (-1, 1):
            for c in (-1, 1):
                p = b["center"] + b["half_size"] * (a * t1 + c * t2)
                assert np.hypot(p[0], p[1]) >= keep_out or p[2] <= -s.mirror.radius


def test_board_layout_is_deterministic_per_seed():
    a = board_layout(_with_scene("sphere", texture_seed=5))
    b = board_layout(_with_scene("sphere", texture_seed=5))
    c = board_layout(_with_scene("sphere", texture_seed=6))
    assert all(np.array_equal(x["center"], y["center"]) for x, y in zip(a, b))
    assert not all(np.array_equal(x["center"], y["center"]) for x, y in zip(a, c))


@pytest.mark.parametrize("lighting, max_depth, expected", [
    ("emissive", 0, 2), ("lit", 0, 3), ("emissive", 5, 5)])
def test_integrator_depth_follows_the_scene(lighting, max_depth, expected):
    assert integrator_depth(_with_scene("sphere", lighting=lighting,
                                        max_depth=max_depth)) == expected


def test_unknown_lighting_is_a_setup_error():
    with pytest.raises(SetupError, match="scene.lighting"):
        _with_scene("sphere", lighting="sunny")


@pytest.mark.slow   # two loads of the paraboloid's 1 M-triangle mesh, ~5 s CPU
def test_emissive_scene_needs_no_more_than_two_bounces():
    """Depth 2 gives the same image as unlimited depth (surfaces are black emitters)."""
    from mitsweep.render import render_image

    s = _with_scene("paraboloid", objects=3)
    s = dataclasses.replace(s, sensor=dataclasses.replace(s.sensor, resolution=(32, 32),
                                                          pixel_pitch=0.32))
    a = render_image(s, "focused", spp=4, seed=1)
    b = render_image(s, "focused", spp=4, seed=1, max_depth=-1)
    np.testing.assert_array_equal(a.image, b.image)


def test_lit_scene_renders_with_light_on_the_walls():
    from mitsweep.render import render_image

    s = _with_scene("sphere", lighting="lit", objects=2)
    s = dataclasses.replace(s, sensor=dataclasses.replace(s.sensor, resolution=(32, 32),
                                                          pixel_pitch=0.288))
    r = render_image(s, "pinhole", spp=8, seed=1, aovs=("mask",))
    assert r.metadata["scene"]["max_depth"] == 3
    assert r.image[r.aovs["mask"] > 0].mean() > 0.01
