"""Strict TOML as docs/reference/setups.md promises: every value typed and named at load time."""

import math
import re

import pytest

from cli_contract import refused
from mitsweep.config import (MAX_NESTING, MAX_RESOLUTION, SetupError, load_setup,
                             setup_from_dict, toml_nesting)

SPHERE_TOML = """\
[mirror]
kind = "sphere"
radius = 25.0
center_distance = 352.0
rim_radius = 25.0

[lens]
focal_length = 50.0
f_number = 2.8

[sensor]
resolution = [512, 512]
pixel_pitch = 0.018

[sweep]
fov_deg = 237.0
depth_min = 300.0
depth_max = 10000.0
velocity = 1.0
"""


def with_line(old: str, new: str) -> str:
    """SPHERE_TOML with the line starting ``old`` replaced by ``new`` (lines, ``\\n``)."""
    lines = SPHERE_TOML.splitlines()
    hits = [i for i, ln in enumerate(lines) if ln.startswith(old)]
    assert len(hits) == 1, old
    lines[hits[0]] = new
    return "\n".join(lines) + "\n"


def appended(section_text: str) -> str:
    return SPHERE_TOML + "\n" + section_text + "\n"


@pytest.fixture
def toml(tmp_path):
    def write(text: str):
        p = tmp_path / "setup.toml"
        p.write_text(text)
        return p
    return write


@pytest.mark.parametrize("text,message", [
    (with_line("radius", 'radius = "25.0"'), "mirror.radius: expected a number, got '25.0'"),
    (with_line("f_number", "f_number = true"), "lens.f_number: expected a number, got True"),
    (with_line("depth_max", 'depth_max = "abc"'),
     "sweep.depth_max: expected a number, got 'abc'"),
    (with_line("depth_max", "depth_max = nan"), "sweep.depth_max: must be a number"),
    (with_line("pixel_pitch", 'pixel_pitch = "0.018"'), "sensor.pixel_pitch: expected a number"),
    (with_line("velocity", "velocity = false"), "sweep.velocity: expected a number, got False"),
    (with_line("center_distance", "center_distance = [352.0]"),
     "mirror.center_distance: expected a number"),
    (with_line("resolution", "resolution = [512.0, 512]"),
     "sensor.resolution width: must be an integer"),
    (with_line("resolution", "resolution = [true, true]"),
     "sensor.resolution width: must be an integer"),
    (with_line("resolution", "resolution = [65536, 65536]"),
     f"sensor.resolution width: must be an integer in [1, {MAX_RESOLUTION}]"),
    (with_line("kind", "kind = 3"), "mirror.kind: must be one of conic, sphere"),
    (appended("[scene]\ntexture_seed = -5"), "scene.texture_seed: must be an integer >= 0"),
    (appended("[scene]\ntexture_seed = 1.5"), "scene.texture_seed: must be an integer"),
    (appended("[scene]\ntexture_seed = \"7\""), "scene.texture_seed: must be an integer"),
    (appended("[scene]\nobjects = true"), "scene.objects: must be an integer in [0, 64]"),
    (appended("[scene]\nlighting = 1"), "scene.lighting: must be one of emissive, lit"),
    (appended("[rig]\nsensor_direction = 1.0"), "rig.sensor_direction: must be 1 or -1"),
    (appended("[rig]\nbaudrate = 9600.0"), "rig.baudrate: must be an integer"),
    (appended("[rig]\nwatchdog_s = true"), "rig.watchdog_s: expected a number"),
    ("name = 5\n" + SPHERE_TOML, "name: must be a string, got 5"),
    (appended("[camera]\niso = 100"), "[camera]: unknown section; allowed sections"),
])
def test_wrong_types_are_refused_naming_the_key(toml, text, message):
    with pytest.raises(SetupError, match=re.escape(message)):
        load_setup(toml(text))


def test_integers_and_infinite_depth_stay_allowed(toml):
    text = with_line("depth_max", "depth_max = inf")
    text = text.replace("radius = 25.0", "radius = 25")      # an integer is a number
    s = load_setup(toml(appended_to(text, "[scene]\ntexture_seed = 0")))
    assert s.sweep.depth_max == math.inf and s.mirror.radius == 25.0
    assert isinstance(s.mirror.radius, float) and s.scene.texture_seed == 0


def appended_to(text: str, section_text: str) -> str:
    return text + "\n" + section_text + "\n"


@pytest.mark.parametrize("where", ["value", "extra-table"])
def test_deep_nesting_is_refused_before_parsing(toml, where):
    deep = "[" * 5000 + "]" * 5000
    text = (with_line("radius", f"radius = {deep}") if where == "value"
            else appended(f"[extra]\nx = {deep}"))
    with pytest.raises(SetupError, match=rf"nested deeper than {MAX_NESTING} levels"):
        load_setup(toml(text))


def test_nesting_just_below_the_cap_reaches_the_type_check(toml):
    nested = "[" * MAX_NESTING + "1.0" + "]" * MAX_NESTING
    with pytest.raises(SetupError, match=r"mirror.radius: expected a number"):
        load_setup(toml(with_line("radius", f"radius = {nested}")))


@pytest.mark.parametrize("text,depth", [
    ("a = [1, [2, [3]]]\n", 3),
    ("[t]\nx = {a = [1]}\n", 2),
    ("[[arr]]\nx = 1\n", 2),
    ('s = "[[[[[[[[[[[["\n', 0),                      # brackets inside strings
    ("s = '[[[[[['\n# [[[[[[[[[[[[\n", 0),           # literal string and comment
    ('s = """\n[[[[[[\n"""\nx = [1]\n', 1),           # multi-line basic string
    ("s = '''[[[[[[''''\n", 0),                      # multi-line literal ending in a quote
    ('s = "esc \\" [[[[[["\n', 0),                   # escaped quote inside a string
])
def test_toml_nesting_skips_strings_and_comments(text, depth):
    assert toml_nesting(text)[0] == depth


def test_nesting_reports_the_line(toml):
    text = appended("[extra]\nx = " + "[" * 20 + "]" * 20)
    line = text[:text.index("\nx = ") + 1].count("\n") + 1
    with pytest.raises(SetupError, match=rf"line {line}: arrays or inline tables nested"):
        load_setup(toml(text))


def test_api_dicts_get_the_same_checks():
    base = {"mirror": {"kind": "sphere", "radius": 25.0, "center_distance": 352.0},
            "sweep": {"fov_deg": 237.0}}
    assert setup_from_dict(base).mirror.radius == 25.0
    bad = {**base, "lens": {"f_number": True}}
    with pytest.raises(SetupError, match="lens.f_number: expected a number, got True"):
        setup_from_dict(bad)


@pytest.mark.parametrize("text,words", [
    (with_line("radius", 'radius = "25.0"'), "mirror.radius"),
    (with_line("depth_max", 'depth_max = "abc"'), "sweep.depth_max"),
    (appended("[extra]\nx = " + "[" * 5000 + "]" * 5000), "nested deeper"),
    (appended("[scene]\ntexture_seed = -5"), "scene.texture_seed"),
])
def test_cli_refuses_in_one_line(toml, capsys, text, words):
    line = refused(capsys, ["sweep-range", toml(text)])
    assert words in line
