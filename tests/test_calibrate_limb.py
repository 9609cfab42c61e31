"""A hemisphere's outline is its limb, where a render shows no edge (the grazing
reflection continues the background behind the mirror): a fit that lands inside it
says so, rather than only blaming the pitch or the distance.

Measured on ``mitsweep render`` images of scenes/sphere.toml at 200 px (pitch 0.06 mm,
32 spp, sweep and pinhole): the renderer's mirror ends at 69.2 px, the predicted limb
69.19 px; the mean luminance steps by 0.12 at 59 px (the boards' reflection ends there,
reflected rays at 114 deg from the axis) and by < 0.01 across the limb; the edge fit
finds 59.0 px (sweep) and 59.3 px (pinhole), -14.7 % and -14.4 %.

The limb itself is found (mitsweep.photo.limb) by what changes there: the fine-detail
energy (a render's noise: inside, a pixel averages the background over hundreds of its
pixels) steps down; per normal the mean steps with a random sign (the local background
against its far average), a ridge of the squared radial derivative fitted as a circle,
then the sign-agnostic steps within 1.5 px fitted with an offset between the two signs.
On renders it meets the issue's bars, pinhole and sweep, 200-1024 px, but for one case
(a strict expected failure below).
"""

import numpy as np
import pytest
from test_calibrate import SMALL, small_setup

from mitsweep.optics.outline import predicted_outline
from mitsweep.photo import calibrate_photo
from mitsweep.optics.pixels import optical_center_px

LIMB_WARNING = "the outline is the mirror's limb"


def disc_photo(radius_px: float, seed: int = 0) -> np.ndarray:
    """Bright inside ``radius_px`` about the axis, the background's level outside (as a
    render, where the reflection near the limb continues the background), with noise."""
    H, W = 200, 200
    rows, cols = np.mgrid[0:H, 0:W]
    r0, c0 = optical_center_px((H, W))
    r = np.hypot(rows - r0, cols - c0)
    img = 0.24 + 0.12 / (1.0 + np.exp((r - radius_px) / 0.8))   # a ~2 px wide edge
    img = img + 0.01 * np.random.default_rng(seed).standard_normal((H, W))
    return np.repeat(img[..., None], 3, axis=-1)


@pytest.fixture(scope="module")
def sphere():
    return small_setup("sphere")


def test_an_edge_inside_the_limb_is_flagged_as_not_the_limb(sphere):
    predicted = predicted_outline(sphere).equivalent_radius_px(SMALL.pixel_pitch)
    cal = calibrate_photo(disc_photo(0.86 * predicted), sphere)
    # the fit finds the edge it was shown (0.5 px: the calibration tests' radius bar)
    assert cal.rim_radius_px == pytest.approx(0.86 * predicted, abs=0.5)
    assert any("pixel pitch would be" in w for w in cal.warnings)
    assert any(LIMB_WARNING in w for w in cal.warnings)


def test_an_edge_at_the_limb_is_not_flagged(sphere):
    predicted = predicted_outline(sphere).equivalent_radius_px(SMALL.pixel_pitch)
    cal = calibrate_photo(disc_photo(predicted), sphere)
    assert cal.rim_radius_px == pytest.approx(predicted, abs=0.5)
    assert not any(LIMB_WARNING in w for w in cal.warnings)


def test_a_rim_outline_is_never_flagged():
    """The paraboloid's outline is its rim (a real edge): a size off by 14 % is the
    setup's pitch or distance, and the warning says only that."""
    s = small_setup("paraboloid")
    assert predicted_outline(s).on_rim.all()
    predicted = predicted_outline(s).equivalent_radius_px(SMALL.pixel_pitch)
    cal = calibrate_photo(disc_photo(0.86 * predicted), s)
    assert any("pixel pitch would be" in w for w in cal.warnings)
    assert not any(LIMB_WARNING in w for w in cal.warnings)


# --- The limb of Mitsuba renders of scenes/sphere.toml (issue 24 item 1) -------------
# The truth: the setup's predicted outline (the renderer's mirror mask matches it to
# 0.03 px at 200 and 400 px, scripts/limb_study.py --check-mask), the axis moved by the
# placement. Placements from scripts/limb_study.py: full frame, off-centre with a
# sub-pixel offset in a larger canvas, and cropped by the frame (12% of the radius
# beyond the limb on the left).

CENTRE_TOL_PX = 0.25
RADIUS_TOL_PX = 0.5


@pytest.fixture(scope="session")
def limb_study():
    """scripts/limb_study.py: the renders, placements and setup of the limb study."""
    import importlib
    import sys

    from conftest import SCENES

    sys.path.insert(0, str(SCENES.parent / "scripts"))
    return importlib.import_module("limb_study")


@pytest.fixture(scope="session")
def sphere_renders(tmp_path_factory, limb_study):
    """Renders (32 spp, full frame, cached for the session) and their calibrations."""
    cache = tmp_path_factory.mktemp("limb_renders")
    done = {}

    def calibrated(size, mode, case):
        if (size, mode, case) not in done:
            img = limb_study.render(size, mode, 32, cache)
            _, canvas, at, sub = next(c for c in limb_study.cases(size) if c[0] == case)
            photo, truth = limb_study.place(img, canvas, at, sub)
            setup = limb_study.sphere_setup(size)
            radius = predicted_outline(setup).equivalent_radius_px(setup.sensor.pixel_pitch)
            done[size, mode, case] = (calibrate_photo(photo, setup), truth, radius)
        return done[size, mode, case]
    return calibrated


#: Cases measured outside the bar (none: ``scripts/limb_study.py --sizes 200 400 1024``,
#: 32 spp, seed 1: pinhole 0.02-0.07 px, sweep 0.08-0.24 px). The sweep render at 1024
#: px cropped by the frame was 0.33 px off (+0.23 row, -0.24 col) while each normal's
#: step was the peak of a smoothed profile's derivative, equally weighted; it is 0.18 px
#: with the blurred step on a ramp fitted to each profile
#: (mitsweep.photo.edges.blurred_step_offsets), weighted by its height.
CENTRE_MISSES: dict = {}


def _limb_params(sizes, misses=None):
    for size in sizes:
        for mode in ("pinhole", "sweep"):
            for case in ("full", "offset", "cropped"):
                marks = []
                if misses and (size, mode, case) in misses:
                    marks.append(pytest.mark.xfail(reason=misses[size, mode, case],
                                                   strict=True))
                # the default run: the 200-px full frames; the rest and known misses in CI
                if size > 200 or case != "full" or marks:
                    marks.append(pytest.mark.slow)
                yield pytest.param(size, mode, case, id=f"{mode}{size}-{case}", marks=marks)


@pytest.mark.parametrize("size, mode, case", list(_limb_params((200, 400, 1024), CENTRE_MISSES)))
def test_the_centre_of_a_sphere_renders_limb(sphere_renders, size, mode, case):
    cal, truth, _ = sphere_renders(size, mode, case)
    assert cal.fit.limb
    assert np.hypot(*np.subtract(cal.center_px, truth)) <= CENTRE_TOL_PX


@pytest.mark.parametrize("size, mode, case", list(_limb_params((200, 400, 1024))))
def test_the_radius_of_a_sphere_renders_limb(sphere_renders, size, mode, case):
    cal, _, radius = sphere_renders(size, mode, case)
    assert cal.fit.limb
    assert abs(cal.rim_radius_px - radius) <= RADIUS_TOL_PX
    # found as the limb: no pitch or distance is blamed beyond the 1% warning level
    assert not any("pixel pitch would be" in w for w in cal.warnings)


#: Over render seeds, not one (scripts/limb_study.py renders with seed 1): at 200 px and
#: 32 spp (full, offset, cropped) the pinhole renders' centres are 0.02-0.07 px off at
#: seeds 1-5, the sweep renders' 0.03-0.24 px (15 of 15 within the bar; 0.01-0.15 at 128
#: spp). Each normal's step was the peak of a smoothed profile's derivative until
#: stop 49: then the pinhole renders were 0.10-0.18 px off and the sweep renders
#: 0.05-0.43 px (7 of 15 within the bar), a bias of +row +col at every seed, the
#: scene's (a 180-degree turn of the photo turned it). The blurred step on a ramp alone
#: (equal weights) left the sweep's 32-spp renders up to 0.30 px off at 200 px, 0.31 at
#: 400 and 0.35 at 1024; weighting each normal by its step's height, 0.24, 0.24, 0.18.
#: (scripts/limb_study.py --sizes 200 --seeds 1 2 3 4 5 [--spp 128])
SEED_FIGURES = "over seeds 1-5 (full, offset, cropped) the sweep renders' centres are " \
               "0.03-0.24 px off (15 of 15 cases within 0.25 px; 0.01-0.15 px at 128 spp)"


def test_the_guide_states_the_sweep_renders_centres_over_seeds():
    """docs/guide/restore.md gives the figures the test below holds."""
    from conftest import SCENES

    text = " ".join((SCENES.parent / "docs" / "guide" / "restore.md").read_text().split())
    assert SEED_FIGURES in text
    assert "At seed 1 a render of the mirror's window only at 200 px is still 0.28 px off" in text
    assert WINDOW_MISSES[200, "sweep"].endswith("the centre 0.28 px off")


@pytest.mark.slow   # 15 renders and calibrations at 200 px
@pytest.mark.parametrize("mode", ["pinhole", "sweep"])
def test_the_centre_of_a_sphere_renders_limb_over_seeds(tmp_path_factory, limb_study,
                                                         mode):
    cache = tmp_path_factory.mktemp("seeds")
    setup = limb_study.sphere_setup(200)
    errors = []
    for seed in range(1, 6):
        img = limb_study.render(200, mode, 32, cache, seed)
        for case in ("full", "offset", "cropped"):
            _, canvas, at, sub = next(c for c in limb_study.cases(200) if c[0] == case)
            photo, truth = limb_study.place(img, canvas, at, sub)
            errors.append(np.hypot(*np.subtract(calibrate_photo(photo, setup).center_px,
                                                truth)))
    assert max(errors) <= CENTRE_TOL_PX, np.round(errors, 2)


@pytest.mark.slow   # two 128-spp renders at 200 px
@pytest.mark.parametrize("seed", [3, 4])
def test_a_clean_sweep_renders_limb_is_found_past_the_boards_energy_step(tmp_path_factory,
                                                                          limb_study, seed):
    """At 128 spp the reflected boards' edge, 14% inside the limb, makes the strongest
    step of the fine-detail energy: the limb's fit from it leaves the searched sizes, and
    the ridges nearest the prediction are tried next (the boards' edge was taken, 10 px
    inside, at these seeds)."""
    setup = limb_study.sphere_setup(200)
    img = limb_study.render(200, "sweep", 128, tmp_path_factory.mktemp("clean"), seed)
    cal = calibrate_photo(img, setup)
    radius = predicted_outline(setup).equivalent_radius_px(setup.sensor.pixel_pitch)
    assert cal.fit.limb
    assert abs(cal.rim_radius_px - radius) <= RADIUS_TOL_PX


#: Renders of only the mirror's window (``mitsweep render`` without ``--full-frame``:
#: exact zeros from 8 px beyond the outline's box, treated as not shown), placed in a
#: larger black canvas. Measured (32 spp, seed 1): pinhole 0.02/0.04 px centre at 200/400
#: px; sweep 0.28 px at 200 px and 0.19 px at 400 px (0.27 and 0.31 px when each
#: normal's step was the peak of a smoothed profile's derivative), radius within 0.03 px.
#: The miss is the render's noise, not the cut background (the test after this one).
WINDOW_MISSES = {(200, "sweep"): "sweep render of the mirror's window only at 200 px, 32 spp, "
                                 "seed 1 (the render's noise: 2 of 5 seeds miss, 0 of 5 at "
                                 "128 spp): the centre 0.28 px off"}


def _on_canvas(img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A square render placed off-centre in a larger black canvas, and its axis there."""
    size = img.shape[0]
    at = (int(0.11 * size), int(0.23 * size))
    canvas = np.zeros((int(1.3 * size), int(1.4 * size), 3), np.float32)
    canvas[at[0]:at[0] + size, at[1]:at[1] + size] = img
    return canvas, np.add(optical_center_px((size, size)), at)


def _window_params():
    for mode in ("pinhole", "sweep"):
        for size in (200, 400):
            marks = [] if (size, mode) == (200, "pinhole") else [pytest.mark.slow]
            if (size, mode) in WINDOW_MISSES:
                marks.append(pytest.mark.xfail(reason=WINDOW_MISSES[size, mode], strict=True))
            yield pytest.param(size, mode, id=f"{mode}-{size}", marks=marks)


@pytest.mark.parametrize("size, mode", list(_window_params()))
def test_the_limb_of_a_render_of_the_mirrors_window(tmp_path_factory, limb_study, size,
                                                    mode):
    img = limb_study.render(size, mode, 32, tmp_path_factory.mktemp("window"),
                            full_frame=False)
    canvas, truth = _on_canvas(img)
    setup = limb_study.sphere_setup(size)
    cal = calibrate_photo(canvas, setup)
    radius = predicted_outline(setup).equivalent_radius_px(setup.sensor.pixel_pitch)
    assert np.hypot(*np.subtract(cal.center_px, truth)) <= CENTRE_TOL_PX
    assert abs(cal.rim_radius_px - radius) <= RADIUS_TOL_PX


@pytest.mark.slow   # 5 renders at 200 px and 40 calibrations, about a minute
def test_the_step_model_beside_the_derivatives_peak(tmp_path, limb_study, capsys):
    """limb.LIMB_STEP_LOCATOR: scripts/limb_study.py runs the blurred-step model and its
    baseline (the derivative's peak, equal weights) on the same sweep renders in one
    process; the model's largest centre error is smaller and no fewer cases are within
    the bar, and docs/guide/restore.md states the figures measured here."""
    import re

    from conftest import SCENES

    assert limb_study.main(["--sizes", "200", "--modes", "sweep", "--seeds", "1", "2", "3",
                            "4", "5", "--locators", "model", "peak",
                            "--cache", str(tmp_path)]) == 0
    got = {}
    for line in capsys.readouterr().out.splitlines():
        m = re.match(r"(model|peak) sweep: centre (\S+)-(\S+) px, (\d+) of (\d+) within", line)
        if m:
            got[m[1]] = (m[2], m[3], int(m[4]), int(m[5]))
    assert got["model"][3] == got["peak"][3] == 20
    assert float(got["model"][1]) < float(got["peak"][1])
    assert got["model"][2] >= got["peak"][2]
    said = (f"the sweep renders' centres are {got['model'][0]}-{got['model'][1]} px off with "
            f"the step model ({got['model'][2]} of 20 within 0.25 px) and "
            f"{got['peak'][0]}-{got['peak'][1]} px with the derivative's peak "
            f"({got['peak'][2]} of 20)")
    text = " ".join((SCENES.parent / "docs" / "guide" / "restore.md").read_text().split())
    assert said in text, said


#: docs/guide/restore.md's account of the window renders' misses, held by the test below.
WINDOW_FIGURES = ("over seeds 1-5 the window's sweep renders at 200 px are 0.09-0.31 px off "
                  "at 32 spp (3 of 5 within 0.25 px) and 0.06-0.17 px at 128 spp")


@pytest.mark.slow   # 20 renders at 200 px (1-4 s each) and their calibrations
def test_a_window_renders_miss_is_its_noise_not_its_cut_background(tmp_path_factory,
                                                                   limb_study):
    """The window render's pixels with the full-frame render's background around them
    miss as the window render does, and the full-frame render cut to the window's mask
    is found as the full frame is: the ~8 px of background left beside the limb is not
    the cause. The window render is another noise draw; over seeds the misses are the
    32-spp noise and go at 128 spp (a ~0.07 px bias of the sweep renders' limb stays)."""
    cache = tmp_path_factory.mktemp("window-seeds")
    setup = limb_study.sphere_setup(200)

    def error(img):
        canvas, truth = _on_canvas(img)
        return float(np.hypot(*np.subtract(calibrate_photo(canvas, setup).center_px, truth)))

    full = limb_study.render(200, "sweep", 32, cache, 1)
    window = limb_study.render(200, "sweep", 32, cache, 1, full_frame=False)
    shown = (window != 0).any(axis=-1, keepdims=True)
    # the background the window leaves beside the limb (restore.md: "about 8 px"),
    # measured from the shown pixels' box to the predicted limb on each side
    rows, cols = np.flatnonzero(shown.any(axis=(1, 2))), np.flatnonzero(shown.any(axis=(0, 2)))
    (r0, c0), R = optical_center_px((200, 200)), predicted_outline(setup).equivalent_radius_px(
        setup.sensor.pixel_pitch)
    margins = [r0 - R - rows[0], rows[-1] - r0 - R, c0 - R - cols[0], cols[-1] - c0 - R]
    assert all(7.5 <= m < 8.5 for m in margins), margins
    # Measured: 0.278 / 0.278 px and 0.080 / 0.080 px (seeds 2-5: within 0.003 px). The
    # 0.01 px allowed is a twentieth of the 0.2 px the two renders' errors differ by, so
    # either swap pointing at the other render would fail.
    assert error(np.where(shown, window, full)) == pytest.approx(error(window), abs=0.01)
    assert error(np.where(shown, full, 0)) == pytest.approx(error(full), abs=0.01)

    errors = {spp: [error(limb_study.render(200, "sweep", spp, cache, seed, full_frame=False))
                    for seed in range(1, 6)] for spp in (32, 128)}
    assert max(errors[128]) <= CENTRE_TOL_PX, np.round(errors[128], 3)
    within = sum(e <= CENTRE_TOL_PX for e in errors[32])
    figures = (f"over seeds 1-5 the window's sweep renders at 200 px are "
               f"{min(errors[32]):.2f}-{max(errors[32]):.2f} px off at 32 spp ({within} of 5 "
               f"within 0.25 px) and {min(errors[128]):.2f}-{max(errors[128]):.2f} px at 128 spp")
    assert figures == WINDOW_FIGURES
    from conftest import SCENES

    text = " ".join((SCENES.parent / "docs" / "guide" / "restore.md").read_text().split())
    assert WINDOW_FIGURES in text


def test_a_limb_at_the_end_of_the_searched_sizes_is_found():
    """A limb 50% larger than the outline (a setup 35% too small predicts it 1/1.54 of
    its size) lies near the top of the sizes searched: its ridge is judged against a
    median window that reaches beyond the range (it was cut off there, and the PAGEOS
    balloon's limb was missed at -35%). The ball: a soft dark-to-bright edge, and inside
    it a faint reflection of a room (sinusoids in the turned direction 2θ, ``r = R sin
    θ``, and the azimuth), squeezed toward the limb as a sphere squeezes it
    (limb.MIN_RADIAL_RISE asks for that)."""
    from mitsweep.photo.free import circle_outline
    from mitsweep.photo.limb import MIN_RADIAL_RISE, fit_limb

    lum, centre, radius = _drawn_ball()
    pts, nrm = circle_outline(200.0).offsets_px(1.0)
    fit = fit_limb(lum, (352.0, 346.0), pts, nrm, (0.7, 1.52))
    assert fit is not None
    # the bars on a limb (radius 0.5 px, centre 0.25 px), as for the renders
    assert fit.radius_px == pytest.approx(radius, abs=RADIUS_TOL_PX)
    assert np.hypot(*np.subtract(fit.center_px, centre)) < CENTRE_TOL_PX
    assert fit.radial_rise >= MIN_RADIAL_RISE


def _drawn_ball(n: int = 700, radius: float = 300.0, centre=(349.3, 350.6), seed: int = 3):
    """A ball (luminance, centre, radius): a soft dark-to-bright edge, and inside it a
    faint reflection of a room (sinusoids in the turned direction 2θ, ``r = R sin θ``,
    and the azimuth), squeezed toward the limb as a sphere squeezes it; noise."""
    rows, cols = np.mgrid[0:n, 0:n]
    r = np.hypot(rows - centre[0], cols - centre[1])
    azimuth = np.arctan2(rows - centre[0], cols - centre[1])
    turned = 2.0 * np.arcsin(np.minimum(r / radius, 1.0))
    rng = np.random.default_rng(seed)
    room = sum(np.sin(rng.uniform(2.0, 6.0) * turned + rng.integers(-8, 9) * azimuth
                      + rng.uniform(0.0, 2.0 * np.pi)) for _ in range(6))
    lum = 0.24 + 0.12 / (1.0 + np.exp((r - radius) / 0.8)) + 0.015 * np.where(r < radius,
                                                                              room, 0.0)
    return lum + 0.01 * rng.standard_normal(lum.shape), centre, radius


def test_a_limb_fitted_on_every_kth_pixel_of_its_annulus_is_the_same_limb():
    """``stride`` (a large photo's limb refined at full resolution near the one found on
    a reduced copy; a 24 MP photo's took minutes on all its pixels): the annulus'
    circles and the direction cues on every 2nd or 3rd pixel row and column, the fit
    along the normals on all of them, give the same limb within the bars; a stride
    below 1 is refused."""
    from mitsweep.photo.free import circle_outline
    from mitsweep.photo.limb import fit_limb

    lum, centre, radius = _drawn_ball()
    pts, nrm = circle_outline(radius).offsets_px(1.0)
    start = (centre[0] + 1.4, centre[1] - 1.1)
    fits = [fit_limb(lum, start, pts, nrm, (0.98, 1.02), stride=k) for k in (1, 2, 3)]
    assert all(f is not None for f in fits)
    for f in fits:
        assert f.radius_px == pytest.approx(radius, abs=RADIUS_TOL_PX)
        assert np.hypot(*np.subtract(f.center_px, centre)) < CENTRE_TOL_PX
    with pytest.raises(ValueError, match="stride"):
        fit_limb(lum, start, pts, nrm, (0.98, 1.02), stride=0)


def test_both_step_locators_find_a_drawn_limb_and_another_is_refused(monkeypatch):
    """limb.LIMB_STEP_LOCATOR: the step model and its baseline, the derivative's peak,
    each find the drawn ball's limb within the bars; a value neither names is refused
    naming both."""
    from mitsweep.photo import limb
    from mitsweep.photo.free import circle_outline

    lum, centre, radius = _drawn_ball()
    pts, nrm = circle_outline(radius).offsets_px(1.0)
    start = (centre[0] + 1.4, centre[1] - 1.1)
    for locator in limb.LIMB_STEP_LOCATORS:
        monkeypatch.setattr(limb, "LIMB_STEP_LOCATOR", locator)
        f = limb.fit_limb(lum, start, pts, nrm, (0.98, 1.02))
        assert f is not None
        assert f.radius_px == pytest.approx(radius, abs=RADIUS_TOL_PX)
        assert np.hypot(*np.subtract(f.center_px, centre)) < CENTRE_TOL_PX
    monkeypatch.setattr(limb, "LIMB_STEP_LOCATOR", "centroid")
    with pytest.raises(ValueError, match="'model', 'peak'"):
        limb.fit_limb(lum, start, pts, nrm, (0.98, 1.02))


def test_the_squeeze_toward_a_limb_is_measured_and_a_flat_disc_has_none():
    """limb.radial_rise on drawn images where the answer is known: a reflection of a
    scene without a preferred direction, squeezed as a sphere squeezes it, rises by
    ~log(1/cos² θ) between the middle and the limb's band; the same detail unsqueezed
    (isotropic noise on a disc) does not rise; a disc whose middle the frame hides is
    undecided (NaN)."""
    from mitsweep.photo.limb import MIN_RADIAL_RISE, radial_rise

    n, R = 400, 150.0
    c = (200.3, 199.6)
    y, x = np.mgrid[0:n, 0:n].astype(float)
    r, azimuth = np.hypot(y - c[0], x - c[1]), np.arctan2(y - c[0], x - c[1])
    turned = 2.0 * np.arcsin(np.minimum(r / R, 1.0))
    rng = np.random.default_rng(0)
    room = sum(np.sin(rng.uniform(3.0, 8.0) * turned + k * azimuth + rng.uniform(0, 6.3))
               for k in range(-6, 7))
    rise = radial_rise(*np.gradient(room), c, R)
    # cos² θ is 0.51-0.75 over [0.5 R, 0.7 R] and 0.04-0.28 over [0.85 R, R - 2]
    assert MIN_RADIAL_RISE < rise < 4.0
    noise = rng.standard_normal((n, n))
    assert abs(radial_rise(*np.gradient(noise), c, R)) < MIN_RADIAL_RISE
    shown = r > 0.75 * R
    assert np.isnan(radial_rise(*np.gradient(room), c, R, shown))


def test_a_refusal_for_contrast_alone_carries_the_outline_it_fitted():
    """The edge fit's refusal of an outline fitted all round but faint says where it was
    (the limb fit's second start): on the real photo without a mirror, a circle on a
    building's facade; a refusal for want of edges (a flat image) carries none."""
    import re
    import warnings

    from real_corpus import corpus

    from mitsweep.io.camera import read_camera_image
    from mitsweep.photo.free import circle_outline
    from mitsweep.photo.rim import NoMirrorError, fit_rim

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        img = read_camera_image(corpus(with_outline=False)[0]["path"]).data
    with pytest.raises(NoMirrorError, match="no clearer an edge") as faint:
        fit_rim(img, circle_outline(76.0), 1.0, starts=1)
    (row, col), radius = faint.value.outline
    H, W = img.shape[:2]
    assert 0 <= row < H and 0 <= col < W
    # the radius the message names (to its 0.1 px), within the sizes searched (±35 %)
    named = float(re.search(r"radius ([0-9.]+) px", str(faint.value)).group(1))
    assert radius == pytest.approx(named, abs=0.05)
    assert 76.0 / 1.35 <= radius <= 76.0 * 1.35
    flat = 0.3 + 0.01 * np.random.default_rng(0).random((200, 200, 3))
    with pytest.raises(NoMirrorError, match="show an edge") as none:
        fit_rim(flat, circle_outline(60.0), 1.0, starts=1)
    assert none.value.outline is None


@pytest.mark.slow     # 18-35 s a size: every start is refined and refused
@pytest.mark.parametrize("radius_px", [60.0, 100.0, 150.0, 220.0])
def test_a_sphere_setup_refuses_a_photo_without_a_mirror(radius_px):
    """The Kodak photo of buildings: the limb fit finds circles on the facades (67-295
    px, their ridge of the radial derivative 2.6-4.0 times its median, as strong as a
    1024-px sweep render's limb), which the detail's direction refuses: just inside
    them it runs along the radius in at most 7 of 12 sectors (a limb: 10 or more)."""
    import warnings
    from dataclasses import replace

    from real_corpus import corpus

    from mitsweep.config import Sensor
    from mitsweep.io.camera import read_camera_image
    from mitsweep.photo import NoMirrorError

    raw = corpus(with_outline=False)[0]["path"]           # buildings, no mirror
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        img = read_camera_image(raw).data
    base = small_setup("sphere")
    H, W = img.shape[:2]
    pitch = predicted_outline(base).equivalent_radius_px(1.0) / radius_px
    setup = replace(base, sensor=Sensor(resolution=(W, H), pixel_pitch=pitch))
    with pytest.raises(NoMirrorError):
        calibrate_photo(img, setup)


@pytest.mark.slow   # 9-14 s each (every start refined and refused, then the wide search)
@pytest.mark.parametrize("share", [0.15, 0.3])
def test_a_limb_fit_run_off_a_photo_without_a_mirror_is_refused_not_a_crash(sphere, share):
    """scikit-image's moon (a real photo shipped with the package) under a sphere setup:
    the limb fit moved its circle off the image, and NumPy raised on a reversed index
    window (predicted 30% of the side; this case fails on the code before the fix) and,
    once the window was clamped, SciPy on a NaN start (15%: the annulus shown on one
    side only); either way a
    CalibrationError (found and refused, or no mirror) is the only allowed outcome."""
    import warnings

    from mitsweep.photo import CalibrationError

    img, setup = _sample_photo_under_a_sphere("moon", sphere, share)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            cal = calibrate_photo(img, setup)
        except CalibrationError:
            return
    assert np.all(np.isfinite(cal.center_px)) and np.isfinite(cal.rim_radius_px)


def _sample_photo_under_a_sphere(name: str, sphere, share: float):
    """scikit-image's sample photo ``name`` (8-bit sRGB, taken as gamma 2.2), linear RGB,
    with the sphere setup resized to it, the limb predicted at ``share`` of its shorter
    side."""
    from dataclasses import replace

    from sample_photos import sample_photo

    from mitsweep.config import Sensor

    img = sample_photo(name)
    H, W = img.shape[:2]
    pitch = predicted_outline(sphere).equivalent_radius_px(1.0) / (share * min(H, W))
    return img, replace(sphere, sensor=Sensor(resolution=(W, H), pixel_pitch=pitch))


#: What a sphere's setup still takes for a mirror in scikit-image's sample photos (none
#: shows one): circles the limb fit finds that pass the direction cues
#: (limb.MIN_RADIAL_SHARE, limb.PARTIAL_SHARE_RIDGE, limb.MIN_RADIAL_RISE), round things
#: whose detail runs along the radius more toward their edge, as a reflection's.
FALSE_MIRRORS = {
    # refused while each normal's step was the peak of a smoothed profile's derivative
    # (a circle 2 px away, detail along the radius in 9 of 12 sectors)
    ("brick", 0.15): "the brick wall: a circle of radius 71 px reads as a limb (detail "
                     "along the radius in 11 of 12 sectors, a ridge 51 times the annulus' "
                     "median, a rise of 1.48)",
    ("astronaut", 0.15): "the astronaut's portrait: a circle of radius 93 px reads as a "
                         "limb (detail along the radius in 12 of 12 sectors, a rise "
                         "of 1.33)",
    ("coffee", 0.3): "a coffee cup's rim (radius 116 px): detail along the radius in 11 "
                     "of 12 sectors, a ridge 35 times the annulus' median, a rise of 1.28",
}


#: The sample-photo cases refused (the limb fit found a circle in each before a cue).
REFUSED_SAMPLES = [
    # the circles the limb fit took for a limb before the direction cue
    ("chelsea", 0.42), ("grass", 0.15), ("grass", 0.3), ("text", 0.3),
    ("moon", 0.3),
    # and those it took with the share of sectors alone (a disagreeing sector, a ridge
    # 0.56-1.70 times the median: limb.PARTIAL_SHARE_RIDGE)
    ("chelsea", 0.3), ("grass", 0.42), ("gravel", 0.15),
    ("gravel", 0.3), ("gravel", 0.42),
    # and those it took with the direction alone (detail along the radius, as much in
    # the middle as at the edge: limb.MIN_RADIAL_RISE)
    ("brick", 0.42), ("text", 0.15),
    # and the cat's eye (a 23.5-px circle the wide search's limb fit took, reported as a
    # mirror 92% off the setup; a rise of -0.41)
    ("chelsea", 0.15)]


@pytest.mark.slow   # 5-30 s a photo (every start refined and refused)
@pytest.mark.parametrize("name, share", [
    *REFUSED_SAMPLES,
    *(pytest.param(*case, marks=pytest.mark.xfail(reason=why, strict=True))
      for case, why in FALSE_MIRRORS.items())])
def test_a_sphere_setup_refuses_sample_photos_without_a_mirror(sphere, name, share):
    """Real photos nobody here made (scikit-image's samples, shipped with it): the limb
    fit found circles in each of these; the detail's direction refuses them."""
    import warnings

    from mitsweep.photo import NoMirrorError

    img, setup = _sample_photo_under_a_sphere(name, sphere, share)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(NoMirrorError):
            calibrate_photo(img, setup)


def test_the_direction_cue_reads_rings_as_a_limb_and_spokes_as_not():
    """limb.radial_share on drawn patterns, where the answer is known: concentric rings
    (detail along the radius, as a reflection squeezed at a limb) read 1 in every sector,
    spokes (detail across it) 0; sectors the frame crops away (under 10 pixels) are not
    counted, so half a ring pattern still reads 1."""
    from mitsweep.photo.limb import radial_share

    n, c, R = 200, (100.0, 100.0), 80.0
    y, x = np.mgrid[0:n, 0:n].astype(float)
    r, th = np.hypot(y - c[0], x - c[1]), np.arctan2(y - c[0], x - c[1])
    rings, spokes = np.sin(2.0 * r), np.sin(40.0 * th)
    assert radial_share(*np.gradient(rings), c, R) == 1.0
    assert radial_share(*np.gradient(spokes), c, R) == 0.0
    shown = np.zeros((n, n), bool)
    shown[:, :100] = True                      # the left half only
    assert radial_share(*np.gradient(rings), c, R, shown) == 1.0
    assert radial_share(*np.gradient(spokes), c, R, shown) == 0.0
    assert radial_share(*np.gradient(rings), c, R, np.zeros((n, n), bool)) == 0.0


def test_the_guide_states_how_many_sample_cases_are_refused():
    """docs/reference/photos.md counts the sample-photo cases the lists above hold (the
    strict expected failures hold them to the code)."""
    from conftest import SCENES

    text = " ".join((SCENES.parent / "docs" / "reference" / "photos.md").read_text().split())
    assert (f"refuses {len(REFUSED_SAMPLES)} of these cases and holds those "
            f"{len(FALSE_MIRRORS)} as strict expected failures") in text
