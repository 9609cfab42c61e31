"""The ``focalsweep`` sensor against Mitsuba's built-in ``thinlens`` and ``perspective``.

Scene: one emissive textured board (a Siemens star) facing the camera, so the only
randomness is pixel and aperture sampling; 48×48 pixels keeps each render well under a
second on the LLVM backend.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import mitsuba as mi  # noqa: E402

from mitsweep.optics.motion import MotionProfile  # noqa: E402
from mitsweep.render.sensor import motion_table, register  # noqa: E402

W = H = 48
PITCH = 0.05     # mm
F = 50.0         # mm
BOARD = 420.0    # mm: distance of the board from the lens
#: Sensor distance (mm) that focuses the board (thin lens: 56.76 mm) ...
I_FOCUS = F * BOARD / (BOARD - F)
#: ... and one 1.24 mm behind it, where the board is out of focus, so that the aperture
#: sample shows in the image (a blur of ~0.4 mm, 8 px, at f/2.8).
I_DEFOCUS = 58.0


@pytest.fixture(scope="module", autouse=True)
def _variant():
    register()


def _scene(sensor: dict, board_distance: float = BOARD) -> "mi.Scene":
    from mitsweep.render.textures import siemens_star

    T = mi.ScalarTransform4f
    return mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 2},
        "sensor": sensor,
        "board": {"type": "rectangle",
                  "to_world": T().translate([0, 0, -board_distance]).scale(40.0),
                  "bsdf": {"type": "diffuse", "reflectance": 0.0},
                  "emitter": {"type": "area", "radiance": {
                      "type": "bitmap", "bitmap": mi.Bitmap(siemens_star(256, 24)),
                      "raw": True}}}})


def _film():
    return {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"},
            "pixel_format": "rgb"}


def _look():
    return mi.ScalarTransform4f().look_at(origin=[0, 0, 0], target=[0, 0, -1], up=[0, 1, 0])


def _focalsweep(spp=16, **kw):
    d = {"type": "focalsweep", "focal_length": F, "pixel_pitch": PITCH, "to_world": _look(),
         "film": _film(), "sampler": {"type": "independent", "sample_count": spp},
         "far_clip": 1e5}
    d.update(kw)
    return d


def _thinlens(i, aperture_radius, spp=16):
    o = F * i / (i - F)
    return {"type": "thinlens", "fov": math.degrees(2 * math.atan(0.5 * W * PITCH / i)),
            "fov_axis": "x", "aperture_radius": aperture_radius, "focus_distance": o,
            "to_world": _look(), "film": _film(),
            "sampler": {"type": "independent", "sample_count": spp}, "far_clip": 1e5}


def _render(scene, seed, spp=None):
    return np.array(mi.render(scene, seed=seed, spp=spp) if spp else mi.render(scene, seed=seed),
                    dtype=np.float64)


@pytest.mark.parametrize("sensor_distance", [56.0, 58.7])
@pytest.mark.parametrize("f_number", [2.8, 11.0])
def test_collapsed_sweep_equals_thinlens_with_same_seed(sensor_distance, f_number):
    a = F / (2 * f_number)
    ours = _render(_scene(_focalsweep(sensor_distance=sensor_distance, f_number=f_number)), 3)
    ref = _render(_scene(_thinlens(sensor_distance, a)), 3)
    # Same samples, same rays up to float32 rounding of o/i (~1e-7 relative): a sample
    # can only change pixel or star sector when it lies within ~1e-5 px of a boundary.
    assert np.max(np.abs(ours - ref)) < 1e-4 * max(1.0, ref.max())
    assert ours.mean() > 0.1  # the board is in view


def test_pinhole_equals_perspective_with_same_seed():
    i = 57.0
    persp = {"type": "perspective", "fov": math.degrees(2 * math.atan(0.5 * W * PITCH / i)),
             "fov_axis": "x", "to_world": _look(), "film": _film(),
             "sampler": {"type": "independent", "sample_count": 8}, "far_clip": 1e5}
    ours = _render(_scene(_focalsweep(spp=8, sensor_distance=i, aperture_radius=0.0)), 5)
    ref = _render(_scene(persp), 5)
    # The pixel sample is the sampler's first 2-D draw for both cameras and the board is
    # seen directly, so the images agree up to float32 rounding (as above).
    assert np.max(np.abs(ours - ref)) < 1e-4 * max(1.0, ref.max())


def _passes(scene, seeds, spp):
    imgs = np.stack([_render(scene, s, spp)[..., 0] for s in seeds])
    return imgs.mean(axis=0), imgs.var(axis=0, ddof=1) / len(seeds)


def test_collapsed_sweep_matches_thinlens_with_other_seeds_statistically():
    i, a = I_DEFOCUS, F / (2 * 2.8)
    m1, v1 = _passes(_scene(_focalsweep(sensor_distance=i, aperture_radius=a)),
                     range(100, 108), 16)
    m2, v2 = _passes(_scene(_thinlens(i, a)), range(200, 208), 16)
    var = v1 + v2
    ok = var > 1e-10
    z2 = (m1 - m2)[ok] ** 2 / var[ok]
    n = int(ok.sum())
    assert n > 500
    # Under H0 z² has mean 1; with 8 passes the variance estimate is itself noisy
    # (z follows a t-like law with ~14 dof: E[z²] ≈ 14/12 ≈ 1.17). Accept a mean of z²
    # within [0.7, 1.6]: a bias of a few percent of the noise already pushes it out.
    assert 0.7 < z2.mean() < 1.6, z2.mean()


@pytest.mark.parametrize("kind", ["linear", "trapezoidal", "tabulated"])
def test_sensor_distance_follows_motion_profile(kind):
    start, end = 58.9, 58.2
    if kind == "linear":
        mp = MotionProfile.linear(start, end)
        extra = {}
    elif kind == "trapezoidal":
        mp = MotionProfile.trapezoidal(start, end, 0.2)
        extra = {"accel_fraction": 0.2}
    else:
        t = np.array([0.0, 0.3, 0.5, 1.0])
        p = np.array([start, 58.7, 58.3, end])
        mp = MotionProfile.tabulated(t, p)
        extra = {"times": " ".join(map(str, t)), "positions": mi.TensorXf(p)}
    sensor = mi.load_dict(_focalsweep(sensor_start=start, sensor_end=end, profile=kind,
                                      shutter_open=0.5, shutter_close=2.5, **extra))
    t = np.linspace(0, 1, 101)
    got = np.array(sensor.sensor_distance(mi.Float(0.5 + 2.0 * t)))
    # float32 holds ~58 mm to ~4e-6 mm; the 65536-interval table adds <= 5e-6 mm at the kinks.
    np.testing.assert_allclose(got, mp.sensor_distance(t), atol=2e-5)


def test_motion_table_is_uniform_in_time():
    mp = MotionProfile.trapezoidal(60.0, 59.0, 0.25)
    tab = motion_table(mp, 8)
    np.testing.assert_allclose(tab, mp.sensor_distance(np.arange(9) / 8))


@pytest.mark.parametrize("params, message", [
    (dict(sensor_distance=I_DEFOCUS, bogus=1.0), "bogus"),
    (dict(sensor_distance=50.0), "focal length"),
    (dict(sensor_start=I_DEFOCUS, sensor_end=49.0, shutter_close=1.0), "focal length"),
    (dict(sensor_distance=I_DEFOCUS, pixel_pitch=0.0), "pixel_pitch"),
    (dict(sensor_distance=I_DEFOCUS, pixel_pitch=-0.01), "pixel_pitch"),
    (dict(sensor_start=I_DEFOCUS, sensor_end=57.0), "shutter_close"),
    (dict(sensor_start=I_DEFOCUS), "sensor_end"),
    (dict(sensor_distance=I_DEFOCUS, f_number=2.0, aperture_radius=1.0), "not both"),
    (dict(sensor_start=I_DEFOCUS, sensor_end=57.0, shutter_close=1.0, profile="sine"),
     "profile"),
])
def test_bad_parameters_raise_clear_errors(params, message):
    with pytest.raises(Exception, match=message):
        mi.load_dict(_focalsweep(**params))


def test_traverse_exposes_parameters_and_updates_render():
    scene = _scene(_focalsweep(sensor_distance=I_DEFOCUS, f_number=4.0))
    params = mi.traverse(scene)
    keys = set(params.keys())
    for k in ("to_world", "aperture_radius", "pixel_pitch", "sensor_distance"):
        assert f"sensor.{k}" in keys
    params["sensor.sensor_distance"] = mi.Float([56.5])
    params.update()
    updated = _render(scene, 7)
    direct = _render(_scene(_focalsweep(sensor_distance=56.5, f_number=4.0)), 7)
    np.testing.assert_allclose(updated, direct, atol=1e-4)
    assert "sensor.sensor_distances" not in keys   # the old key is gone, not aliased


@pytest.mark.parametrize("kind", ["linear", "trapezoidal", "tabulated"])
def test_traverse_updates_of_the_sweep_equal_a_freshly_loaded_sweep(kind):
    """Changing the sweep through mi.traverse renders what loading it directly renders."""
    def sweep(start, end):
        extra = {"profile": kind}
        if kind == "trapezoidal":
            extra["accel_fraction"] = 0.3
        elif kind == "tabulated":
            extra.update(times="0 0.5 1", positions=f"{start} {start + 0.3} {end}")
        return _focalsweep(sensor_start=start, sensor_end=end, shutter_close=1.0,
                           f_number=4.0, **extra)

    scene = _scene(sweep(58.9, 58.2))
    params = mi.traverse(scene)
    if kind == "tabulated":
        params["sensor.positions"] = mi.Float([57.0, 57.3, 58.0])
    else:
        params["sensor.sensor_start"] = mi.Float(57.0)
        params["sensor.sensor_end"] = mi.Float(58.0)
    params.update()
    assert scene.sensors()[0].motion_span == pytest.approx((57.0, 58.0))
    np.testing.assert_allclose(_render(scene, 7), _render(_scene(sweep(57.0, 58.0)), 7),
                               atol=1e-4)


def test_traverse_refuses_a_sweep_end_inside_the_focal_length():
    scene = _scene(_focalsweep(sensor_start=58.9, sensor_end=58.2, shutter_close=1.0))
    params = mi.traverse(scene)
    params["sensor.sensor_end"] = mi.Float(49.0)
    with pytest.raises(ValueError, match="focal"):
        params.update()


def test_sweep_blurs_between_its_end_focus_images():
    """A sweep image lies between its two end-focused images in sharpness."""
    i_focus = I_FOCUS
    a = F / (2 * 2.0)
    sharp = _render(_scene(_focalsweep(sensor_distance=i_focus, aperture_radius=a)), 1)
    sweep = _render(_scene(_focalsweep(sensor_start=i_focus - 0.6, sensor_end=i_focus + 0.6,
                                       shutter_close=1.0, aperture_radius=a)), 1)
    far = _render(_scene(_focalsweep(sensor_distance=i_focus + 0.6, aperture_radius=a)), 1)

    def contrast(img):
        return float(np.abs(np.diff(img[..., 0], axis=1)).mean())

    assert contrast(far) < contrast(sweep) < contrast(sharp)


@pytest.mark.parametrize("kw", [
    dict(sensor_distance=I_DEFOCUS, aperture_radius=0.0),
    dict(sensor_distance=I_DEFOCUS, f_number=2.8),
    dict(sensor_start=I_DEFOCUS - 0.5, sensor_end=I_DEFOCUS + 0.5, shutter_close=1.0,
         f_number=2.8),
], ids=["pinhole", "thinlens", "sweep"])
def test_light_tracing_through_sample_direction_matches_path_tracing(kw):
    """``ptracer`` (which connects to the camera via sample_direction) = ``path``."""
    from mitsweep.render.textures import siemens_star

    def scene(integrator):
        T = mi.ScalarTransform4f
        return mi.load_dict({
            "type": "scene", "integrator": {"type": integrator, "max_depth": 2},
            "sensor": _focalsweep(spp=512, **kw),
            "board": {"type": "rectangle", "to_world": T().translate([0, 0, -420]).scale(40.0),
                      "bsdf": {"type": "diffuse", "reflectance": {
                          "type": "bitmap", "bitmap": mi.Bitmap(siemens_star(256, 12)),
                          "raw": True}}},
            "light": {"type": "directional", "direction": [0.3, 0.2, -1], "irradiance": 1.0}})

    a = _render(scene("path"), 1)[..., 0]
    ptracer = scene("ptracer")
    b1 = _render(ptracer, 1)[..., 0]
    b2 = _render(ptracer, 2)[..., 0]
    blocks = lambda x: x.reshape(6, 8, 6, 8).mean(axis=(1, 3))  # noqa: E731
    # The path tracer is nearly noise-free here (direct light, no aperture noise at the
    # block scale); the light tracer's 8×8-block noise is ~5 %. Compare the squared
    # block error against the light tracer's own variance from two seeds: the ratio
    # follows ~F(36, 36) under H0 (99th percentile ≈ 2.2); a wrong pixel mapping (flip,
    # scale by i/o) makes it ≫ 3. The mean catches a wrong normalisation (image area,
    # 1/i²). The cos³θ factor is not tested here: it varies by < 0.1 % over this field.
    err = np.mean((blocks(b1) - blocks(a)) ** 2)
    noise = np.mean((blocks(b1) - blocks(b2)) ** 2) / 2
    assert err < 2.5 * noise, (err, noise)
    assert 0.5 * (b1.mean() + b2.mean()) == pytest.approx(a.mean(), rel=0.03)


def test_plugin_loads_from_mitsuba_xml_with_a_tabulated_motion():
    xml = f"""<scene version="3.0.0">
      <sensor type="focalsweep">
        <float name="focal_length" value="{F}"/>
        <float name="f_number" value="4"/>
        <float name="pixel_pitch" value="{PITCH}"/>
        <float name="sensor_start" value="58.9"/>
        <float name="sensor_end" value="58.2"/>
        <string name="profile" value="tabulated"/>
        <string name="times" value="0, 0.5, 2"/>
        <string name="positions" value="58.9 58.8 58.2"/>
        <float name="shutter_open" value="0"/>
        <float name="shutter_close" value="1"/>
        <transform name="to_world"><lookat origin="0,0,0" target="0,0,-1" up="0,1,0"/></transform>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
      </sensor>
    </scene>"""
    scene = mi.load_string(xml)
    sensor = scene.sensors()[0]
    got = np.array(sensor.sensor_distance(mi.Float([0.0, 0.25, 1.0])))
    np.testing.assert_allclose(got, [58.9, 58.8, 58.2], atol=1e-5)


def test_register_again_after_a_variant_change(tmp_path):
    """Registration is per variant: a new variant needs (and gets) its own."""
    import subprocess
    import sys

    code = (
        "import mitsuba as mi\n"
        "from mitsweep.render import register\n"
        "register()\n"
        "mi.set_variant('scalar_rgb')\n"
        "register()\n"
        "s = mi.load_dict({'type': 'focalsweep', 'focal_length': 50.0, 'pixel_pitch': 0.02,"
        f" 'sensor_distance': {I_DEFOCUS!r},"
        " 'film': {'type': 'hdrfilm', 'width': 4, 'height': 4}})\n"
        "ray, w = s.sample_ray(0.0, 0.5, mi.Point2f(0.5, 0.5), mi.Point2f(0.5, 0.5))\n"
        "print(mi.variant(), abs(ray.d[2] - 1.0) < 1e-6)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["scalar_rgb", "True"]
