"""Real photos at large sizes (the issue's first report: a 16 MP JPEG of a chrome ball was
refused). The corpus' real photos (tests/data/real, at most 1232 px) enlarged
k times (bilinear): the same outline with k times wider edges and k times the pixels,
as a high-resolution camera's soft edge. The reference (tests/test_real_corpus.py) maps
to ``(c + 0.5) k - 0.5`` and its tolerance to k times its own.

Photos from 1536 px on their shorter side are searched on a copy reduced by a whole
factor (:func:`mitsweep.photo.rim.working_factor`) and refined at full resolution near
what was found there. Measured before that (the search at full resolution, 2 cores):
sphere_tokyo.jpg x1.5 3.2 px off (tolerance 2.4) in 13 s, x2 (5.6 MP) 8.2 px off in 20 s,
x3.5 (17 MP) 24 px off in 321 s, sphere_lamp.jpg x3 in 41 s; after: 0.7 px in 5 s, 0.5 px
in 7 s, 1.9 px (tolerance 5.6) in 7 s, 6 s. ``scripts/bench_large_photos.py`` runs both
paths side by side.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest
from test_calibrate_real import _rough_setup

from mitsweep.photo import calibrate_photo
from mitsweep.photo.free import find_circle

from conftest import SCENES

sys.path.insert(0, str(SCENES.parent / "scripts"))
import bench_large_photos  # noqa: E402

#: The enlarged photos still missed (none at present). omni_kaidan.jpg x2 (1280x960:
#: searched as it is) and x4 (searched at 1/2, as x2) were: the mount's edge, 15% outside
#: the mirror's rim (65 and 131 px), was found first (the +9% guess lies between the
#: two), and the coarse search's other starts were 30-50 px off centre and never reached
#: the rim, until the starts about the first fit's centre (rim.CONCENTRIC_STARTS; the
#: test after the smoothing's). sphere_lamp.jpg x3 was listed, its radius 1.92 px off
#: against a tolerance of 1.79, until the refinement at full resolution smoothed the edge
#: profiles as much as the working size does (rim.REFINE_SMOOTHING_GROWS: 1.18 px).
LARGE_MISSES: dict[tuple[str, float], str] = {}

CASES = [("sphere_tokyo.jpg", 1.5), ("sphere_tokyo.jpg", 2), ("sphere_tokyo.jpg", 3.5),
         ("sphere_lamp.jpg", 2), ("sphere_lamp.jpg", 3), ("paraboloid_mei.jpg", 2.5),
         ("omni_vmr_clipped.jpg", 3), ("omni_kaidan.jpg", 2), ("omni_kaidan.jpg", 4)]


def _params():
    for name, k in CASES:
        marks = [pytest.mark.slow]
        if (name, k) in LARGE_MISSES:
            marks.append(pytest.mark.xfail(reason=LARGE_MISSES[name, k], strict=True))
        yield pytest.param(name, k, id=f"{name}x{k:g}", marks=marks)


@pytest.mark.parametrize("name, k", list(_params()))
def test_a_large_photo_calibrates(name, k):
    img, entry = bench_large_photos.enlarged(name, k)
    cal = calibrate_photo(img, _rough_setup(entry, img.shape[:2], 0.09))
    tol = entry["tolerance_px"]
    assert np.abs(np.subtract(cal.center_px, entry["centre"])).max() < tol
    assert abs(cal.rim_radius_px - entry["radius"]) < tol


@pytest.mark.slow
def test_free_finds_a_chrome_ball_on_a_large_photo():
    img, entry = bench_large_photos.enlarged("sphere_tokyo.jpg", 3.5)
    fit, radius = find_circle(img)
    tol = entry["tolerance_px"]
    assert np.abs(np.subtract(fit.center_px, entry["centre"])).max() < tol
    assert abs(radius - entry["radius"]) < tol


@pytest.mark.slow
def test_the_large_photo_benchmark_prints_both_paths(capsys):
    """scripts/bench_large_photos.py on one case: the reduced and the full-resolution
    search side by side, each within the tolerance, and a total per path."""
    assert bench_large_photos.main(["--cases", "sphere_lamp.jpg:1.6"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert [line.split()[3] for line in out[:2]] == ["reduced", "full"]
    assert all("PASS" in line for line in out[:2])
    assert out[2].startswith("reduced: 1 of 1 within tolerance")
    assert out[3].startswith("full: 1 of 1 within tolerance")


#: The chrome balls' enlargements the refinement's smoothing is compared on (the docs'
#: figures; scripts/bench_large_photos.py's CASES).
BALLS = ["sphere_tokyo.jpg:1.5", "sphere_tokyo.jpg:2", "sphere_tokyo.jpg:3.5",
         "sphere_lamp.jpg:2", "sphere_lamp.jpg:3", "sphere_lamp.jpg:4"]


@pytest.mark.slow   # 45 s: 6 large photos, two refinements each
def test_the_refinement_smooths_as_the_working_size_does(capsys):
    """rim.REFINE_SMOOTHING_GROWS against the working size's smoothing in full-resolution
    pixels (scripts/bench_large_photos.py, both paths, the same process): on the
    enlarged chrome balls the grown smoothing's largest error is smaller and no fewer
    balls are within tolerance with it; docs/reference/photos.md states the figures
    measured here (which cases got worse, the largest errors, the passes)."""
    import re

    assert bench_large_photos.main(["--cases", *BALLS, "--paths", "reduced",
                                    "fixed-smoothing"]) == 0
    err: dict[str, list[float]] = {"reduced": [], "fixed-smoothing": []}
    passes = {"reduced": 0, "fixed-smoothing": 0}
    worse = []
    for line in capsys.readouterr().out.splitlines():
        m = re.match(r"(\S+)\s+x(\S+)\s+\S+\s+(reduced|fixed-smoothing)\s+\S+ s\s+"
                     r"(PASS|MISS)\s+centre\s+(\S+) radius\s+(\S+) px", line)
        if m:
            err[m[3]].append(max(float(m[5]), float(m[6])))
            passes[m[3]] += m[4] == "PASS"
            # each case prints its reduced line first (the --paths order above)
            if m[3] == "fixed-smoothing" and err["reduced"][-1] > err[m[3]][-1]:
                worse.append((m[1], m[2], err[m[3]][-1], err["reduced"][-1]))
    assert len(err["reduced"]) == len(err["fixed-smoothing"]) == len(BALLS)
    assert max(err["reduced"]) < max(err["fixed-smoothing"])
    assert passes["reduced"] >= passes["fixed-smoothing"]
    text = " ".join((SCENES.parent / "docs" / "reference" / "photos.md").read_text().split())
    n = len(BALLS)
    said = (f"on the chrome balls enlarged 1.5-4 times ({n} cases), the larger of the "
            f"centre's and the radius' error falls in {n - len(worse)} and rises in "
            f"{len(worse)} (" + "; ".join(f"{name} enlarged {k} times, {a:.2f} → {b:.2f} px"
                                          for name, k, a, b in worse)
            + f"); its largest, {max(err['fixed-smoothing']):.2f} → "
              f"{max(err['reduced']):.2f} px, and {passes['reduced']} of {n} within "
              f"tolerance, against {passes['fixed-smoothing']}")
    assert said in text, said


#: The enlargements of the photo whose mount's edge was taken for its rim.
KAIDAN = ["omni_kaidan.jpg:2", "omni_kaidan.jpg:4"]


@pytest.mark.slow   # 15 s: 2 large photos, two searches each
def test_a_rim_inside_its_mount_is_found_about_the_first_fits_centre(capsys):
    """rim.CONCENTRIC_STARTS against the search without it (scripts/bench_large_photos.py,
    both paths, the same process): on omni_kaidan.jpg enlarged 2 and 4 times the rim is
    found with it and the mount's edge, 15% outside, without; docs/reference/photos.md
    states the figures measured here."""
    import re

    assert bench_large_photos.main(["--cases", *KAIDAN, "--paths", "reduced",
                                    "no-concentric"]) == 0
    got: dict[str, list[tuple[str, float, float, float]]] = {"reduced": [],
                                                             "no-concentric": []}
    for line in capsys.readouterr().out.splitlines():
        m = re.match(r"\S+\s+x\S+\s+\S+\s+(reduced|no-concentric)\s+\S+ s\s+(PASS|MISS)\s+"
                     r"centre\s+(\S+) radius\s+(\S+) px \(tolerance (\S+)\)", line)
        if m:
            got[m[1]].append((m[2], float(m[3]), float(m[4]), float(m[5])))
    assert [g[0] for g in got["reduced"]] == ["PASS", "PASS"]
    assert [g[0] for g in got["no-concentric"]] == ["MISS", "MISS"]
    (_, c2, r2, t2), (_, c4, r4, t4) = got["reduced"]
    (_, _, m2, _), (_, _, m4, _) = got["no-concentric"]
    said = (f"on omni_kaidan.jpg enlarged 2 and 4 times the rim is found {max(c2, r2):.2f} "
            f"and {max(c4, r4):.2f} px off (tolerance {t2:.2f} and {t4:.2f}); without them "
            f"the mount's edge is taken, its radius {m2:.2f} and {m4:.2f} px off")
    text = " ".join((SCENES.parent / "docs" / "reference" / "photos.md").read_text().split())
    assert said in text, said


def test_the_working_size_and_what_the_docs_say_of_it():
    """The reduction starts at 1.5 working sides and rounds to the nearest factor; the
    docs state the threshold and the enlargements the tests cover, and cannot drift."""
    from mitsweep.photo.rim import WORKING_SIDE_PX, working_factor

    first = int(1.5 * WORKING_SIDE_PX)
    assert working_factor((first - 1, 10 * first)) == 1
    assert working_factor((first, first)) == 2
    assert working_factor((4000, 6000, 3)) == 4        # 24 MP: searched at 1000x1500
    assert working_factor((1, 5000)) == 1              # never below 1
    text = (SCENES.parent / "docs" / "reference" / "photos.md").read_text()
    text = " ".join(text.split())
    balls = [k for name, k in CASES if name.startswith("sphere_")]
    assert f"A photo from {first} px on its shorter side" in text
    assert f"chrome balls enlarged {min(balls):g}-{max(balls):g} times" in text
    assert f"keeps {['no', 'one', 'two', 'three', 'four'][len(LARGE_MISSES)]} strict " \
           "expected failures" in text
    project = " ".join((SCENES.parent / "docs" / "reference" / "project.md").read_text().split())
    ks = [k for _, k in CASES]
    assert f"enlarged {min(ks):g}-{max(ks):g} times" in project


@pytest.mark.parametrize("limb", [False, True], ids=["edge", "limb"])
def test_a_refused_refinement_keeps_the_reduced_fit_in_full_resolution_pixels(limb):
    """A flat photo shows no edge and no limb at full resolution: the fit found on the
    copy reduced 3x stands, its reduced pixel (r, c) mapped to the centre of its 3x3
    block, (3r + 1, 3c + 1), and its lengths tripled."""
    from mitsweep.photo.free import circle_outline
    from mitsweep.photo.rim import RimFit, refine_at_full_resolution

    found = RimFit(center_px=(100.0, 120.5), scale=1.02, points_used=1000,
                   points_total=1440, residual_rms_px=0.3,
                   edge_points_px=np.array([[10.0, 20.0]]), center_se_px=0.05,
                   edge_width_px=1.5, residual_tolerance_px=1.5, limb=limb)
    flat = np.full((600, 720), 0.3)
    fit = refine_at_full_resolution(flat, circle_outline(240.0), 1.0 / 3, found, 3)
    assert fit.center_px == (301.0, 362.5)
    assert fit.scale == found.scale and fit.limb == limb
    np.testing.assert_array_equal(fit.edge_points_px, [[31.0, 61.0]])
    assert (fit.residual_rms_px, fit.center_se_px, fit.edge_width_px) == \
        pytest.approx((0.9, 0.15, 4.5))


def test_a_limb_found_on_a_reduced_copy_is_refined_at_full_resolution():
    """A limb found on a copy reduced 2x, 0.3 reduced pixels off (0.6 px), is refined at
    full resolution to the issue's bars: the refinement's circles are fitted to every
    2nd pixel row and column of the annulus (limb.fit_limb's ``stride``: a 24 MP photo's
    refinement took minutes on all of them), the normals' fit to all."""
    from test_calibrate_limb import CENTRE_TOL_PX, RADIUS_TOL_PX, _drawn_ball

    from mitsweep.photo.free import circle_outline
    from mitsweep.photo.rim import RimFit, refine_at_full_resolution

    lum, centre, radius = _drawn_ball()
    reduced = ((centre[0] - 0.5) / 2 + 0.3, (centre[1] - 0.5) / 2 - 0.2)
    found = RimFit(center_px=reduced, scale=1.0, points_used=1400, points_total=1440,
                   residual_rms_px=0.3, edge_points_px=np.zeros((0, 2)), center_se_px=0.05,
                   edge_width_px=1.5, residual_tolerance_px=1.5, limb=True)
    fit = refine_at_full_resolution(lum, circle_outline(radius), 1.0, found, 2)
    assert fit.limb
    assert np.hypot(*np.subtract(fit.center_px, centre)) < CENTRE_TOL_PX
    assert abs(fit.scale * radius - radius) < RADIUS_TOL_PX
