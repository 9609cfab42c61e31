"""The motion-profile file: round trips, the format's rules, the stage's limits."""

import json
from dataclasses import replace

import numpy as np
import pytest

from mitsweep.config import SetupError, load_setup
from mitsweep.optics.motion import MotionProfile
from mitsweep.optics.motion_file import (FORMAT, VERSION, check_motion_file, load_motion_file,
                                         parse_motion_file, save_motion_file, stage_kinematics)

SCENES = __import__("pathlib").Path(__file__).resolve().parents[1] / "scenes"


def _doc(**over):
    doc = {"format": FORMAT, "version": VERSION, "times": [0.0, 0.25, 1.0],
           "sensor_distances_mm": [366.0, 366.1, 366.5], "exposure_s": 0.5,
           "provenance": {"generator": "test"}}
    doc.update(over)
    return doc


@pytest.mark.parametrize("profile", [
    MotionProfile.linear(366.0, 366.5),
    MotionProfile.tabulated([0, 2, 3, 7], [366.5, 366.3, 366.2, 366.0]),
    MotionProfile.trapezoidal(366.0, 366.5, 0.2),
])
def test_round_trip_keeps_the_motion(tmp_path, profile):
    path = save_motion_file(tmp_path / "m.json", profile, exposure_s=0.5,
                            provenance={"generator": "test", "seed": 3})
    mf = load_motion_file(path)
    assert mf.profile.kind == "tabulated"
    assert mf.exposure_s == 0.5 and mf.provenance == {"generator": "test", "seed": 3}
    t = np.linspace(0, 1, 1001)
    # linear and tabulated: exact knots; trapezoidal: 256 chords per ramp, whose error
    # bound |Δi| a / (8 n² (1 − a)) is 2e-7 mm here
    tol = 1e-12 if profile.kind != "trapezoidal" else 3e-7
    np.testing.assert_allclose(mf.profile.sensor_distance(t), profile.sensor_distance(t),
                               rtol=0, atol=tol)
    assert mf.profile.midpoint == pytest.approx(profile.midpoint, abs=1e-12)
    assert not list(tmp_path.glob(".m.json.*"))  # no temporary left behind


def test_save_replaces_atomically_and_leaves_no_temporary(tmp_path):
    p = tmp_path / "m.json"
    save_motion_file(p, MotionProfile.linear(366.0, 366.5), exposure_s=None, provenance={})
    save_motion_file(p, MotionProfile.linear(366.0, 367.0), exposure_s=None, provenance={})
    assert load_motion_file(p).profile.span == (366.0, 367.0)
    assert load_motion_file(p).exposure_s is None
    assert sorted(x.name for x in tmp_path.iterdir()) == ["m.json"]


def test_unserialisable_provenance_writes_nothing(tmp_path):
    p = tmp_path / "m.json"
    with pytest.raises(SetupError, match="provenance"):
        save_motion_file(p, MotionProfile.linear(366.0, 366.5), exposure_s=1.0,
                         provenance={"x": float("nan")})
    assert not p.exists() and not list(tmp_path.iterdir())


@pytest.mark.parametrize("over, message", [
    ({"times": [], "sensor_distances_mm": []}, "empty table"),
    ({"times": [0.0], "sensor_distances_mm": [366.0]}, "at least 2"),
    ({"times": [0.0, 1.0]}, "2 times but 3 sensor distances"),
    ({"times": [0.0, 0.5, 0.5], "sensor_distances_mm": [366.0, 366.1, 366.2]}, "last 1"),
    ({"times": [0.0, 0.6, 0.5, 1.0], "sensor_distances_mm": [366, 366.1, 366.2, 366.3]},
     "strictly increasing"),
    ({"times": [0.1, 0.5, 1.0]}, "first must be 0"),
    ({"sensor_distances_mm": [366.0, 366.2, 366.1]}, "strictly monotonic"),
    ({"sensor_distances_mm": [366.0, 366.0, 366.1]}, "strictly monotonic"),
    ({"sensor_distances_mm": [-1.0, 366.0, 366.1]}, "> 0 mm"),
    ({"format": "something-else"}, "format must be"),
    ({"version": 2}, "version 2 is not supported"),
    ({"exposure_s": -1}, "exposure_s"),
    ({"exposure_s": "fast"}, "exposure_s"),
    ({"provenance": [1, 2]}, "provenance must be a JSON object"),
    ({"speed": 3}, "unknown key"),
    ({"times": ["0", 0.5, 1]}, "list of numbers"),
])
def test_bad_tables_are_one_line_errors(over, message):
    with pytest.raises(SetupError, match=message) as err:
        parse_motion_file(json.dumps(_doc(**over)), source="p.json")
    assert "\n" not in str(err.value) and str(err.value).startswith("motion file p.json: ")


def test_nan_and_broken_json_are_refused():
    text = json.dumps(_doc()).replace("366.1", "NaN")
    with pytest.raises(SetupError, match="NaN"):
        parse_motion_file(text, source="p.json")
    with pytest.raises(SetupError, match="not valid JSON"):
        parse_motion_file("{", source="p.json")
    with pytest.raises(SetupError, match="missing key"):
        parse_motion_file(json.dumps({"format": FORMAT, "version": 1}))


def test_stage_kinematics_of_a_known_profile():
    # 0.1 mm in the first quarter, 0.4 mm in the rest, over 2 s: 0.2 and 0.2667 mm/s;
    # the change is made within the shorter interval beside the knot, 0.25 · 2 s = 0.5 s
    # (the rig's rule), not over the midpoints' distance (1 s)
    p = MotionProfile.tabulated([0, 0.25, 1], [366.0, 366.1, 366.5])
    v, a = stage_kinematics(p, 2.0)
    np.testing.assert_allclose(v, [0.2, 0.4 / 1.5], rtol=1e-12)
    np.testing.assert_allclose(a, [(0.4 / 1.5 - 0.2) / 0.5], rtol=1e-12)


@pytest.fixture(scope="module")
def setup():
    return load_setup(SCENES / "paraboloid.toml")


def test_check_accepts_a_followable_profile(setup):
    mf = parse_motion_file(json.dumps(_doc()), source="p.json")
    assert check_motion_file(mf, setup) is mf


def test_check_refuses_a_span_crossing_the_focal_length(setup):
    f = setup.lens.focal_length
    mf = parse_motion_file(json.dumps(_doc(sensor_distances_mm=[f - 1, f + 1, f + 2])))
    with pytest.raises(SetupError, match="focal length"):
        check_motion_file(mf, setup)


def test_check_refuses_what_the_stage_cannot_follow(setup):
    # 0.5 mm in 0.05 s: 8 and 10.7 mm/s against rig.max_velocity = 5 mm/s
    mf = parse_motion_file(json.dumps(_doc(exposure_s=0.05)))
    with pytest.raises(SetupError, match="rig.max_velocity"):
        check_motion_file(mf, setup)
    # the same shape with no exposure is only a shape: nothing to check the stage against
    check_motion_file(parse_motion_file(json.dumps(_doc(exposure_s=None))), setup)
    # 0.8 then 1.067 mm/s, changed within 0.25 s: 1.07 mm/s² > 0.1 mm/s²
    slow = replace(setup, rig=replace(setup.rig, acceleration=0.1))
    with pytest.raises(SetupError, match="rig.acceleration"):
        check_motion_file(parse_motion_file(json.dumps(_doc())), slow)
    with pytest.raises(SetupError, match="rig.travel"):
        check_motion_file(parse_motion_file(json.dumps(_doc())),
                          replace(setup, rig=replace(setup.rig, travel=0.2)))
    with pytest.raises(SetupError, match="exposure 40 s"):
        check_motion_file(parse_motion_file(json.dumps(_doc(exposure_s=40.0))), setup)
