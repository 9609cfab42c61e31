"""Setup files: strict loading, validation messages that name the key and the range."""

import math

import pytest

from mitsweep.config import (DEFAULT_SETUP, SetupError, load_setup, setup_from_dict,
                             setup_to_dict)

BASE = {
    "mirror": {"kind": "conic", "radius": 25.0, "conic": 0.0, "rim_radius": 25.0,
               "vertex_distance": 327.0, "tilt_deg": 0.0},
    "lens": {"focal_length": 50.0, "f_number": 2.8},
    "sweep": {"fov_deg": 237.0, "depth_min": 300.0, "depth_max": 10000.0, "velocity": 1.0},
}


def _with(section, **changes):
    data = {k: dict(v) for k, v in BASE.items()}
    data.setdefault(section, {}).update(changes)
    return data


@pytest.mark.parametrize("name", ["sphere", "paraboloid", "paraboloid_tilted"])
def test_shipped_setups_load(scenes_dir, name):
    s = load_setup(scenes_dir / f"{name}.toml")
    assert s.name == name


def test_sphere_kind_normalises_to_conic(scenes_dir):
    s = load_setup(scenes_dir / "sphere.toml")
    assert (s.mirror.radius, s.mirror.conic, s.mirror.vertex_distance) == (25.0, 0.0, 327.0)
    assert s.mirror == DEFAULT_SETUP.mirror


def test_paraboloid_kind_uses_twice_the_focal_length(scenes_dir):
    s = load_setup(scenes_dir / "paraboloid.toml")
    assert s.mirror.radius == pytest.approx(28.2) and s.mirror.conic == -1.0


def test_round_trip_through_dict():
    s = setup_from_dict(BASE)
    again = setup_from_dict({k: v for k, v in setup_to_dict(s).items()})
    assert again == s


@pytest.mark.parametrize("section,key,value,message", [
    ("lens", "f_number", 0.0, r"lens.f_number: must be > 0"),
    ("lens", "f_number", -2.0, r"lens.f_number: must be > 0"),
    ("lens", "focal_length", math.nan, r"lens.focal_length: must be finite"),
    ("sweep", "depth_min", 20000.0, r"sweep.depth_min: must be <= sweep.depth_max"),
    ("sweep", "fov_deg", 400.0, r"sweep.fov_deg: must be in \(0, 360\)"),
    ("sweep", "velocity", 0.0, r"sweep.velocity: must be > 0"),
    ("sweep", "profile", "sine", r"sweep.profile: must be one of linear"),
    ("mirror", "radius", -5.0, r"mirror.radius: must be > 0"),
    ("mirror", "tilt_deg", 95.0, r"mirror.tilt_deg: must be in \(-90, 90\)"),
    ("mirror", "vertex_distance", -10.0, r"mirror.vertex_distance: must be > 0"),
    ("mirror", "vertex_distance", 40.0, r"must be > lens.focal_length"),
    ("mirror", "rim_radius", 30.0, r"mirror.rim_radius: must be <= 25"),
    ("mirror", "radius", "big", r"mirror.radius: expected a number"),
    ("rig", "watchdog_s", 0.0, r"rig.watchdog_s: must be > 0"),
    ("rig", "watchdog_s", 61.0, r"rig.watchdog_s: must be in \(0, 60\] s"),
    ("scene", "unit", "km", r"scene.unit: must be one of mm, cm, m"),
    ("scene", "file", "", r"scene.file: must be a path to a Mitsuba XML file"),
    ("scene", "placement", {"shift": [0, 0, 1]},
     r"scene.placement.shift: unknown key; allowed keys: rotate_deg, translate"),
    ("scene", "placement", {"translate": [0, 1]}, r"scene.placement.translate: must be \[x, y, z\]"),
    ("scene", "placement", {"rotate_deg": [0, "a", 0]}, r"scene.placement.rotate_deg: expected a number"),
    ("scene", "placement", [0, 0, 1], r"scene.placement: must be a table"),
])
def test_bad_values_name_key_and_range(section, key, value, message):
    with pytest.raises(SetupError, match=message):
        setup_from_dict(_with(section, **{key: value}))


def test_rig_watchdog_defaults_to_one_second_and_is_read():
    assert setup_from_dict(BASE).rig.watchdog_s == 1.0
    assert setup_from_dict(dict(BASE, rig={"watchdog_s": 2.5})).rig.watchdog_s == 2.5


def test_unknown_key_is_rejected_with_the_allowed_ones():
    with pytest.raises(SetupError, match=r"lens.focal_lenght: unknown key; allowed keys: "
                                         r"f_number, focal_length"):
        setup_from_dict(_with("lens", focal_lenght=50.0))


def test_unknown_section_is_rejected():
    data = dict(BASE, camera={"x": 1})
    with pytest.raises(SetupError, match=r"\[camera\]: unknown section; allowed sections: "
                                         r"mirror, lens"):
        setup_from_dict(data)


@pytest.mark.parametrize("section,key", [("mirror", "radius"), ("sweep", "fov_deg")])
def test_missing_required_key(section, key):
    data = {k: dict(v) for k, v in BASE.items()}
    del data[section][key]
    with pytest.raises(SetupError, match=rf"{section}.{key}: missing"):
        setup_from_dict(data)


def test_not_toml_and_missing_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[mirror\nradius = ")
    with pytest.raises(SetupError, match="not a valid TOML file"):
        load_setup(bad)
    with pytest.raises(SetupError, match="no such setup file"):
        load_setup(tmp_path / "nope.toml")


def test_focus_override_needs_both_ends():
    with pytest.raises(SetupError, match="give both focus_min and focus_max"):
        setup_from_dict(_with("sweep", focus_min=340.0))
    with pytest.raises(SetupError, match="sweep.focus_min: must be > lens.focal_length"):
        setup_from_dict(_with("sweep", focus_min=40.0, focus_max=360.0))


def test_setup_is_frozen():
    s = setup_from_dict(BASE)
    with pytest.raises(Exception):
        s.lens.f_number = 4.0  # type: ignore[misc]


def test_user_scene_keys_round_trip_and_resolve_beside_the_setup(tmp_path, monkeypatch):
    """[scene] file is relative to the setup file (not the working directory); unit and
    placement survive TOML and dict round trips; a setup without them is unchanged."""
    from mitsweep.config import Placement, setup_to_toml

    data = _with("scene", file="worlds/garden.xml", unit="m",
                 placement={"translate": [0.0, -20.0, 5.0], "rotate_deg": [90.0, 0.0, 0.0]})
    s = setup_from_dict(data)
    assert s.scene.placement == Placement(translate=(0.0, -20.0, 5.0), rotate_deg=(90.0, 0.0, 0.0))
    (tmp_path / "rig").mkdir()
    path = tmp_path / "rig" / "s.toml"
    path.write_text(setup_to_toml(s))
    monkeypatch.chdir(tmp_path)
    loaded = load_setup(path)
    assert loaded.scene.file == str(tmp_path / "rig" / "worlds" / "garden.xml")
    assert loaded.scene.unit == "m" and loaded.scene.placement == s.scene.placement
    assert setup_from_dict(setup_to_dict(loaded)) == loaded
    assert {"file", "unit", "placement"}.isdisjoint(setup_to_dict(setup_from_dict(BASE))["scene"])
