"""The ``focalsweep`` sensor in the scalar variant, tested as in the vectorised ones.

The same plugin code runs in both (:mod:`mitsweep.render.focalsweep`: one class over the
variant's array type). Where the same sampler makes it exact, ``scalar_rgb`` is checked
as ``llvm_ad_rgb`` is in ``test_render_sensor.py`` (a collapsed sweep is ``thinlens``
with the same seed, a pinhole a zero-aperture ``thinlens``); the motion and the rays are compared
with ``llvm_ad_rgb``'s sample for sample; a sweep image agrees with ``llvm_ad_rgb``'s
within Monte Carlo noise (the two variants' samplers draw different streams).

The module switches to ``scalar_rgb`` and back (and re-registers mitsweep's plugins).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import mitsuba as mi

from mitsweep.optics.motion import MotionProfile
from mitsweep.render import register

W = H = 12
PITCH = 0.2      # mm
F = 50.0         # mm
BOARD = 420.0    # mm
I_DEFOCUS = 58.0
MOTIONS = {
    "fixed": {"sensor_distance": I_DEFOCUS},
    "linear": {"sensor_start": 58.9, "sensor_end": 58.2},
    "trapezoidal": {"sensor_start": 58.9, "sensor_end": 58.2, "profile": "trapezoidal",
                    "accel_fraction": 0.2},
    "tabulated": {"sensor_start": 58.9, "sensor_end": 58.2, "profile": "tabulated",
                  "times": "0 0.3 0.5 1", "positions": "58.9 58.7 58.3 58.2"},
}
#: Film samples (x, y), aperture samples and normalised times shared by both variants.
SAMPLES = np.random.default_rng(4).random((64, 5))


def _look():
    return mi.ScalarTransform4f().look_at(origin=[0, 0, 0], target=[0, 0, -1], up=[0, 1, 0])


def _film():
    return {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"},
            "pixel_format": "rgb"}


def _focalsweep(spp=4, **kw):
    d = {"type": "focalsweep", "focal_length": F, "pixel_pitch": PITCH, "to_world": _look(),
         "film": _film(), "sampler": {"type": "independent", "sample_count": spp},
         "far_clip": 1e5}
    if "sensor_start" in kw:  # a moving sensor needs an exposure interval
        d.update(shutter_open=0.0, shutter_close=1.0)
    d.update(kw)
    return d


def _thinlens(i, aperture_radius, spp=4):
    o = F * i / (i - F)
    return {"type": "thinlens", "fov": math.degrees(2 * math.atan(0.5 * W * PITCH / i)),
            "fov_axis": "x", "aperture_radius": aperture_radius, "focus_distance": o,
            "to_world": _look(), "film": _film(),
            "sampler": {"type": "independent", "sample_count": spp}, "far_clip": 1e5}


def _scene(sensor):
    from mitsweep.render.textures import siemens_star

    T = mi.ScalarTransform4f
    return mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 2}, "sensor": sensor,
        "board": {"type": "rectangle", "to_world": T().translate([0, 0, -BOARD]).scale(40.0),
                  "bsdf": {"type": "diffuse", "reflectance": 0.0},
                  "emitter": {"type": "area", "radiance": {
                      "type": "bitmap", "bitmap": mi.Bitmap(siemens_star(64, 12)),
                      "raw": True}}}})


def _render(scene, seed, spp=None):
    img = mi.render(scene, seed=seed, spp=spp) if spp else mi.render(scene, seed=seed)
    return np.array(img, dtype=np.float64)


def _rays(sensor) -> np.ndarray:
    """Origin, direction and sensor distance of the rays for SAMPLES, one row each."""
    rows = []
    for x, y, a, b, t in SAMPLES:
        x, y, a, b, t = map(float, (x, y, a, b, t))
        ray, _ = sensor.sample_ray(t, 0.5, mi.Point2f(x, y), mi.Point2f(a, b))
        i = sensor.sensor_distance(mi.Float(t))
        rows.append(np.r_[np.ravel(ray.o), np.ravel(ray.d), np.ravel(i)])
    return np.array(rows, dtype=np.float64)


def _blocks(img, n=3):
    """Means of n×n pixel blocks of the red channel."""
    r = img[..., 0]
    return r.reshape(H // n, n, W // n, n).mean(axis=(1, 3))


@pytest.fixture(scope="module")
def vectorised():
    """What llvm_ad_rgb gives: rays per motion, and block means of sweep renders."""
    register()
    mi.set_variant("llvm_ad_rgb")
    register()
    rays = {k: _rays(mi.load_dict(_focalsweep(**m))) for k, m in MOTIONS.items()}
    blocks = np.array([_blocks(_render(_scene(_focalsweep(**MOTIONS["linear"])), s, 16))
                       for s in range(8)])
    return rays, blocks


@pytest.fixture(scope="module")
def scalar(vectorised):
    before = mi.variant()
    mi.set_variant("scalar_rgb")
    assert register() == "scalar_rgb"
    yield
    mi.set_variant(before)
    register()


@pytest.mark.parametrize("kind", list(MOTIONS))
def test_scalar_rays_equal_the_vectorised_ones(vectorised, scalar, kind):
    got = _rays(mi.load_dict(_focalsweep(**MOTIONS[kind])))
    # The scalar motion is evaluated in double precision, the vectorised one in float32
    # (58 mm to ~4e-6 mm); the rays are float32 in both.
    np.testing.assert_allclose(got, vectorised[0][kind], rtol=0, atol=2e-5)


@pytest.mark.parametrize("kind", ["linear", "trapezoidal", "tabulated"])
def test_scalar_sensor_distance_follows_motion_profile(scalar, kind):
    m = MOTIONS[kind]
    if kind == "linear":
        mp = MotionProfile.linear(m["sensor_start"], m["sensor_end"])
    elif kind == "trapezoidal":
        mp = MotionProfile.trapezoidal(m["sensor_start"], m["sensor_end"], 0.2)
    else:
        mp = MotionProfile.tabulated([0, 0.3, 0.5, 1], [58.9, 58.7, 58.3, 58.2])
    sensor = mi.load_dict(_focalsweep(**m))
    t = np.linspace(0, 1, 41)
    got = [sensor.sensor_distance(float(x)) for x in t]
    # double precision; the trapezoid's 65536-interval table adds <= 5e-6 mm at its kinks
    np.testing.assert_allclose(got, mp.sensor_distance(t), atol=1e-5)


@pytest.mark.parametrize("f_number", [2.8, 11.0])
def test_scalar_collapsed_sweep_equals_thinlens_with_same_seed(scalar, f_number):
    i, a = I_DEFOCUS, F / (2 * f_number)
    ours = _render(_scene(_focalsweep(sensor_distance=i, f_number=f_number)), 3)
    ref = _render(_scene(_thinlens(i, a)), 3)
    assert np.max(np.abs(ours - ref)) < 1e-4 * max(1.0, ref.max())
    assert ours.mean() > 0.1


def test_scalar_pinhole_equals_a_zero_aperture_thinlens_with_same_seed(scalar):
    """In the scalar variant a pixel's samples come one after another from one random
    stream, so a camera that draws an aperture sample (``focalsweep``, ``thinlens``)
    shifts the next sample's pixel position against one that does not
    (``perspective``: equal only within noise there); a zero-aperture ``thinlens``
    draws the same numbers (in the vectorised variants every sample is its own lane,
    and ``test_render_sensor.py`` compares with ``perspective``)."""
    i = 57.0
    ours = _render(_scene(_focalsweep(sensor_distance=i, aperture_radius=0.0)), 5)
    ref = _render(_scene(_thinlens(i, 0.0)), 5)
    assert np.max(np.abs(ours - ref)) < 1e-4 * max(1.0, ref.max())
    assert ours.mean() > 0.1


def test_scalar_sweep_agrees_with_the_vectorised_one_within_monte_carlo_noise(
        vectorised, scalar):
    theirs = vectorised[1]
    ours = np.array([_blocks(_render(_scene(_focalsweep(**MOTIONS["linear"])), s, 16))
                     for s in range(100, 108)])
    se = np.hypot(ours.std(axis=0, ddof=1), theirs.std(axis=0, ddof=1)) / np.sqrt(len(ours))
    z = (ours.mean(axis=0) - theirs.mean(axis=0)) / np.maximum(se, 1e-12)
    assert np.all(np.abs(z) < 5), z
    assert ours.mean() > 0.1


def test_scalar_variant_exposes_no_differentiable_parameter(scalar):
    sensor = mi.load_dict(_focalsweep(**MOTIONS["linear"]))
    assert sensor.differentiable_parameters() == ()
    assert sensor.differentiated_parameters() == ()
    assert set(mi.traverse(sensor).keys()) == {"to_world"}
