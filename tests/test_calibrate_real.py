"""Calibration on real photographs of curved mirrors taken by other people's cameras
(``tests/data/real``, see its SOURCES.md), against references measured independently of
mitsweep (scikit-image Canny + RANSAC circle, ``tests/test_real_corpus.py``).

Two paths: ``calibrate --free`` (no setup: a circle from the photo alone) and
``calibrate_photo`` with a setup that is only roughly right (the bundled setup of the
photo's mirror kind, its pitch chosen so that the predicted outline is 9% larger than
the photo's, as a user's guess before calibrating would be). Each asserts the centre and
radius within the reference's stated tolerance (3 sd of the reference + 0.5 px).
"""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest
from real_corpus import corpus

from mitsweep.config import Sensor, load_setup
from mitsweep.io.camera import read_camera_image
from mitsweep.optics.outline import predicted_outline
from mitsweep.optics.pixels import optical_center_px
from mitsweep.photo import calibrate_photo
from mitsweep.photo.free import find_circle

from conftest import SCENES

#: Photos on which ``--free`` does not find the reference outline yet, and why (measured
#: with this release; strict: a fix must update this list).
FREE_KNOWN_FAILURES: dict[str, str] = {}

#: Photos whose ``--free`` search runs in the default run (the others, 2-4 s each, in
#: CI's slow run): a limb, a paraboloid's rim and, through the CLI
#: (test_free_cli_prints_the_circle_and_a_setup_skeleton), a rim cut by the frame.
FREE_DEFAULT = {"sphere_lamp.jpg", "paraboloid_mei.jpg"}

PHOTOS = corpus(with_outline=True)


def _read(entry) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return read_camera_image(entry["path"]).data


def _free_marks(name: str) -> list:
    marks = [] if name in FREE_DEFAULT else [pytest.mark.slow]
    if name in FREE_KNOWN_FAILURES:
        marks.append(pytest.mark.xfail(reason=FREE_KNOWN_FAILURES[name], strict=True))
    return marks


@pytest.mark.parametrize("entry", [pytest.param(e, id=e["name"], marks=_free_marks(e["name"]))
                                   for e in PHOTOS])
def test_free_calibration_finds_the_reference_circle(entry):
    fit, radius = find_circle(_read(entry))
    tol = entry["tolerance_px"]
    assert np.abs(np.asarray(fit.center_px) - entry["centre"]).max() < tol
    assert abs(radius - entry["radius"]) < tol
    # a limb (no edge stands out) is looked for last, and only a sphere has one
    assert not fit.limb or entry["mirror"] == "sphere"


@pytest.mark.slow   # 2 s
@pytest.mark.parametrize("entry", [pytest.param(e, id=e["name"]) for e in PHOTOS
                                   if e["semi_axes"] is not None])
def test_free_reports_the_ellipse_of_an_elliptical_outline(entry):
    """An outline whose reference is an ellipse (the dome: semi-axes 8 px apart, its rim
    seen off its axis): the ellipse ``--free`` reports through the circle fit's edges
    (:func:`mitsweep.photo.free.ellipse_of_edges`) has the reference's centre and
    semi-axes within the reference's tolerances (the orientation of an ellipse this
    round, axis ratio 0.99, is not held: the reference's seeds alone differ by 2.7 deg
    and the two methods' by 8-10, 135 deg clockwise here against 125-127)."""
    from mitsweep.photo.free import ellipse_of_edges

    fit, _ = find_circle(_read(entry))
    ellipse = ellipse_of_edges(fit)
    assert ellipse is not None and ellipse["significant"]
    assert np.abs(np.asarray(ellipse["center_px"]) - entry["centre"]).max() \
        < entry["tolerance_px"]
    assert np.abs(np.asarray(ellipse["semi_axes_px"]) - entry["semi_axes"]).max() \
        < entry["axes_tolerance_px"]


def _rough_setup(entry, shape, error: float):
    """The bundled setup of the photo's mirror kind, on the photo's frame, with the
    centre offset and a pitch such that its outline is ``1 + error`` times the
    reference's."""
    name = "sphere" if entry["mirror"] == "sphere" else "paraboloid"
    base = load_setup(SCENES / f"{name}.toml")
    H, W = shape
    predicted_at_1mm = predicted_outline(base).equivalent_radius_px(1.0)
    pitch = predicted_at_1mm / (entry["radius"] * (1.0 + error))
    return replace(base, sensor=Sensor(resolution=(W, H), pixel_pitch=pitch))


#: Rough-setup calibrations that do not meet the reference's tolerance yet, and why.
SETUP_KNOWN_FAILURES: dict[str, str] = {}


#: Misses at some guesses only (the photo calibrates at the others). Each of the coarse
#: search's starting points is refined (a mount's inner edge nearer the guess than the
#: rim is one of them, paraboloid_mei at -35%) and the best supported fit wins; what
#: still fails:
GUESS_FAILURES: dict[tuple[str, float], str] = {}
# (the dome, dome_store_bright_rim.jpg, was listed at all three guesses, 1.37-2.33 px from
# a circle reference whose RANSAC consensus kept the sectors nearest one radius of an
# elliptical outline; its reference is now the ellipse, see tests/test_real_corpus.py)


#: Photos whose +9% guess runs in CI's slow run only: the largest sphere (1184 px, ~30 s
#: on 2 cores), omni_kaidan, sphere_pageos_nasa and the dome (7-10 s each: their outline
#: is found only after the other starting points are refined and refused), and
#: paraboloid_mei and paraboloid_mei_2 (5-6 s each). The default run keeps a real limb
#: (sphere_lamp) and a paraboloid's rim cut by the frame (omni_vmr_clipped).
SLOW_PHOTOS = {"sphere_tokyo.jpg", "omni_kaidan.jpg", "sphere_pageos_nasa.png",
               "dome_store_bright_rim.jpg", "paraboloid_mei.jpg", "paraboloid_mei_2.jpg"}


def _rough_cases():
    for e in PHOTOS:
        for error in (0.09, -0.35, 0.35):
            # the default run: the +9% guess on every photo but SLOW_PHOTOS (in CI's slow
            # run with the ±35% ends)
            marks = [] if error == 0.09 and e["name"] not in SLOW_PHOTOS else [pytest.mark.slow]
            why = SETUP_KNOWN_FAILURES.get(e["name"]) or GUESS_FAILURES.get((e["name"], error))
            if why:   # a known miss: checked in CI's slow run, not before every commit
                marks += [pytest.mark.xfail(reason=why, strict=True), pytest.mark.slow]
            yield pytest.param(e, error, id=f"{e['name']}{error:+.2f}", marks=marks)


@pytest.mark.parametrize("entry, error", list(_rough_cases()))
def test_a_rough_setup_calibrates_the_real_photo(entry, error):
    """A 9% guess in the default run; the ±35% ends of the range the search covers in CI."""
    img = _read(entry)
    setup = _rough_setup(entry, img.shape[:2], error=error)
    cal = calibrate_photo(img, setup)
    tol = entry["tolerance_px"]
    assert np.abs(np.asarray(cal.center_px) - entry["centre"]).max() < tol
    assert abs(cal.rim_radius_px - entry["radius"]) < tol
    # the guess is reported, with the pitch that would make the prediction right
    assert any("pixel pitch would be" in w for w in cal.warnings)
    assert cal.implied_pixel_pitch == pytest.approx(setup.sensor.pixel_pitch * (1 + error),
                                                    rel=tol / entry["radius"])


def test_free_cli_prints_the_circle_and_a_setup_skeleton(capsys):
    import json

    from mitsweep.cli.main import main

    entry = next(e for e in PHOTOS if e["name"] == "omni_vmr_clipped.jpg")
    assert main(["calibrate", str(entry["path"]), "--free", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert np.abs(np.asarray(out["center_px"]) - entry["centre"]).max() \
        < entry["tolerance_px"]
    H, W = entry["shape"]
    r0, c0 = optical_center_px((H, W))
    np.testing.assert_allclose(out["center_offset_px"],
                               np.asarray(out["center_px"]) - (r0, c0), atol=1e-9)
    assert f"resolution = [{W}, {H}]" in out["setup_skeleton"]


@pytest.mark.slow   # 20 s: every circle and ellipse is refined and refused first
def test_free_cli_finds_the_pageos_limb_and_says_so(capsys):
    """The PAGEOS balloon's limb shows no edge that stands out (its draped top): --free
    finds it as a limb, within the reference's tolerance, and says so."""
    import json

    from mitsweep.cli.main import main

    entry = next(e for e in PHOTOS if e["name"] == "sphere_pageos_nasa.png")
    assert main(["calibrate", str(entry["path"]), "--free", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["limb"] is True
    assert np.abs(np.asarray(out["center_px"]) - entry["centre"]).max() < entry["tolerance_px"]
    assert main(["calibrate", str(entry["path"]), "--free"]) == 0
    assert "a sphere's limb" in capsys.readouterr().out


@pytest.mark.slow   # 23 s (every start refined and refused); test_calibrate.py's refusal stays
def test_free_cli_refuses_a_photo_without_a_mirror(capsys):
    from cli_contract import refused

    raw = corpus(with_outline=False)[0]["path"]  # buildings, no mirror
    line = refused(capsys, ["calibrate", str(raw), "--free"])
    assert line.startswith("mitsweep: error: no mirror found")
    assert "setup" not in line          # --free has none: the message does not ask for one


@pytest.mark.parametrize("side", [20, 48])
def test_free_cli_refuses_a_tiny_photo_in_one_line(tmp_path, capsys, side):
    from PIL import Image
    from cli_contract import refused

    photo = tmp_path / "tiny.png"
    noise = np.random.default_rng(side).random((side, side, 3))
    Image.fromarray((noise * 255).astype(np.uint8)).save(photo)
    line = refused(capsys, ["calibrate", str(photo), "--free"])
    assert "radius_range_px" not in line and ("no mirror found" in line or "32x32" in line)


def test_the_guide_states_the_counts_these_lists_give():
    """docs/reference/photos.md says how many photos each path finds: the counts the
    expected-failure lists above imply (which the strict xfails hold to the code)."""
    text = " ".join((SCENES.parent / "docs" / "reference" / "photos.md").read_text().split())
    n = len(PHOTOS)
    assert f"`--free` finds {n - len(FREE_KNOWN_FAILURES)} of the {n}" in text
    for error, label in ((0.09, "+9 %"), (-0.35, "−35 %"), (0.35, "+35 %")):
        found = sum(1 for e in PHOTOS if e["name"] not in SETUP_KNOWN_FAILURES
                    and (e["name"], error) not in GUESS_FAILURES)
        assert f"by {label} {found} of the {n}" in text, label


def test_the_rough_setup_benchmark_prints_both_searches(capsys):
    """scripts/bench_rough_setups.py on one photo and guess: a line per search, a total."""
    import importlib.util

    path = SCENES.parent / "scripts" / "bench_rough_setups.py"
    spec = importlib.util.spec_from_file_location("bench_rough_setups", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    assert bench.main(["--photos", "omni_vmr_clipped.jpg", "--guesses", "0.35"]) == 0
    out = capsys.readouterr().out
    for starts in (1, 6):
        assert f"+0.35 starts {starts}" in out
        assert f"starts {starts}: 1 of 1 within tolerance" in out


def test_the_recorded_corpus_table_follows_the_references_and_the_lists():
    """docs/reference/photo_corpus.json (scripts/photo_corpus.py, the docs' corpus table)
    holds the references of references.json and finds what the lists above say: a
    record left stale by a change of the code or of a reference fails here."""
    import json

    rows = {r["name"]: r for r in json.loads(
        (SCENES.parent / "docs" / "reference" / "photo_corpus.json").read_text())}
    assert sorted(rows) == sorted(e["name"] for e in PHOTOS)
    for e in PHOTOS:
        r = rows[e["name"]]
        assert r["centre_px"] == list(e["centre"]) and r["radius_px"] == e["radius"]
        assert r["tolerance_px"] == e["tolerance_px"]
        assert r["runs"]["free"]["within_tolerance"] == (e["name"] not in FREE_KNOWN_FAILURES)
        for error in (0.09, -0.35, 0.35):
            expected = (e["name"] not in SETUP_KNOWN_FAILURES
                        and (e["name"], error) not in GUESS_FAILURES)
            assert r["runs"][f"{error:+.2f}"]["within_tolerance"] == expected, (e["name"], error)
